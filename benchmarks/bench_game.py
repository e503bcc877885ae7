"""Overhead of the game layers over the raw Gymnasium env, measured side by side in one run.

Three ways of stepping HalfCheetah-v5 with uniformly random actions (drawn before timing):

* ``raw``: ``gymnasium.make("HalfCheetah-v5")`` (its default wrappers), ``env.step``.
* ``view``: the protagonist's `SingleAgentView` of preset ``state-gauss-0.1`` with an embedded
  `GaussianAdversary` (σ = 0.1) on the observation: a sense move and an act move per step.
* ``parallel``: the full PettingZoo `Game.step` of preset ``default`` (bounded observation and
  action adversaries), random actions for all three agents, two moves per step.

Each is timed for ``--steps`` protagonist steps, in ``--rounds`` interleaved rounds (raw, view,
parallel, raw, ...) so machine noise hits all three alike. Reported: the best round of each
(steps/s) with its ratio to the best raw round, and the median over rounds of each round's own
ratio (view and parallel against the raw run just before them), which drifting load skews
less. Run: ``python benchmarks/bench_game.py --rounds 5``.
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
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (args.steps, 6)).astype(np.float32)
    adv_obs = rng.uniform(-1, 1, (args.steps, 17)).astype(np.float32)
    adv_act = rng.uniform(-1, 1, (args.steps, 6)).astype(np.float32)
    runs: dict[str, list[float]] = {"raw": [], "view": [], "parallel": []}
    for r in range(args.rounds):
        runs["raw"].append(bench_raw(actions))
        runs["view"].append(bench_view(actions))
        runs["parallel"].append(bench_parallel(actions, adv_obs, adv_act))
        print(
            f"round {r + 1}/{args.rounds}: "
            + ", ".join(f"{k} {v[-1]:,.0f}" for k, v in runs.items())
        )
    report(runs, args.steps)


def report(runs: dict[str, list[float]], steps: int) -> None:
    """Best round of each (steps/s), its ratio to the best raw round, the median per-round ratio."""
    raw = max(runs["raw"])
    print(f"\n{ENV}, {steps} steps x {len(runs['raw'])} rounds (steps/s; ratios to raw):")
    print(f"  {'':29s} {'best':>10s}  {'best/best':>9s}  {'median of rounds':>16s}")
    print(f"  {'raw gymnasium env':29s} {raw:10,.0f}  {1.0:9.3f}  {1.0:16.3f}")
    for key, label, goal in (
        ("view", "protagonist view + N(0,0.1)", 0.95),
        ("parallel", "ParallelEnv, obs+act advs", 0.90),
    ):
        best = max(runs[key])
        median = float(np.median([v / r for v, r in zip(runs[key], runs["raw"], strict=True)]))
        print(f"  {label:29s} {best:10,.0f}  {best / raw:9.3f}  {median:16.3f}  (goal >= {goal})")


if __name__ == "__main__":
    main()
