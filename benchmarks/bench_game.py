"""Overhead of the game layers over the raw Gymnasium env, measured side by side in one run.

Three ways of stepping HalfCheetah-v5 with uniformly random actions (drawn before timing):

* ``raw``: ``gymnasium.make("HalfCheetah-v5")`` (its default wrappers), ``env.step``.
* ``view``: the protagonist's `SingleAgentView` of preset ``state-gauss-0.1`` with an embedded
  `GaussianAdversary` (σ = 0.1) on the observation: a sense move and an act move per step.
* ``parallel``: the full PettingZoo `Game.step` of preset ``default`` (bounded observation and
  action adversaries), random actions for all three agents, two moves per step.

Each is timed for ``--steps`` protagonist steps, in ``--rounds`` interleaved rounds (raw, view,
parallel, raw, ...) so machine noise hits all three alike; the best round of each is reported
(steps/s) with its ratio to raw. Run: ``python benchmarks/bench_game.py``.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import advgame
from advgame.adversaries import GaussianAdversary
from advgame.views import SingleAgentView

ENV = "HalfCheetah-v5"


def bench_raw(actions: np.ndarray) -> float:
    env = gym.make(ENV)
    env.reset(seed=0)
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def bench_view(actions: np.ndarray) -> float:
    game = advgame.make(ENV, preset="state-gauss-0.1")
    env = SingleAgentView(
        game, "protagonist", {"observation_adversary": GaussianAdversary(std=0.1)}
    )
    env.reset(seed=0)
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def bench_parallel(actions: np.ndarray, adv_obs: np.ndarray, adv_act: np.ndarray) -> float:
    game = advgame.make(ENV, preset="default")
    game.reset(seed=0)
    steps = 0
    start = time.perf_counter()
    while steps < len(actions):
        move = {
            "protagonist": actions[steps],
            "observation_adversary": adv_obs[steps],
            "action_adversary": adv_act[steps],
        }
        if game.move == "act":
            steps += 1
        game.step(move)
        if not game.agents:
            game.reset()
    return len(actions) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (args.steps, 6)).astype(np.float32)
    adv_obs = rng.uniform(-1, 1, (args.steps, 17)).astype(np.float32)
    adv_act = rng.uniform(-1, 1, (args.steps, 6)).astype(np.float32)
    best = {"raw": 0.0, "view": 0.0, "parallel": 0.0}
    for r in range(args.rounds):
        best["raw"] = max(best["raw"], bench_raw(actions))
        best["view"] = max(best["view"], bench_view(actions))
        best["parallel"] = max(best["parallel"], bench_parallel(actions, adv_obs, adv_act))
        print(
            f"round {r + 1}/{args.rounds}: " + ", ".join(f"{k} {v:,.0f}" for k, v in best.items())
        )
    raw = best["raw"]
    print(f"\n{ENV}, {args.steps} steps x {args.rounds} rounds, best round (steps/s):")
    print(f"  raw gymnasium env            {raw:10,.0f}   1.000")
    print(
        f"  protagonist view + N(0,0.1)  {best['view']:10,.0f}   {best['view'] / raw:.3f}  (goal >= 0.95)"
    )
    print(
        f"  ParallelEnv, obs+act advs    {best['parallel']:10,.0f}   {best['parallel'] / raw:.3f}  (goal >= 0.90)"
    )


if __name__ == "__main__":
    main()
