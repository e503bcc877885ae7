"""Training throughput of the multi-agent protagonist learners on MA-HalfCheetah-2x3, side by side.

Five measurements in one run, in interleaved rounds so that machine noise hits them alike:

* ``raw``: ``gymnasium_robotics.mamujoco_v1.parallel_env("HalfCheetah", "2x3")`` stepped with
  random actions drawn before timing (the simulator and MaMuJoCo's factorization only).
* ``team view``: `advgame.core.team.TeamView` of preset ``default`` (bounded observation and action
  adversaries, each playing a `GaussianAdversary`, σ = 0.05), random protagonist actions: a
  sense move and an act move per step.
* ``MAPPO`` / ``IPPO``: `TeamLearner` with the paper's table (2048 steps per rollout, 10
  epochs of minibatches of 64, [64, 64]) on that team view, ``--steps`` environment steps per
  round: collection (actor and critic inference per step) plus updates.
* ``shared IPPO (SB3)``: `SharedIPPO`, SB3 PPO with the same table on SuperSuit's
  agents-as-envs vectorisation of the team view (one policy for both agents).

Steps per second are environment (team) steps; the best round of each is reported. One torch
thread, as in training runs. Run: ``python benchmarks/bench_marl.py`` (``--steps``,
``--rounds``, ``--n-envs``).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
import torch

from advgame.adversaries import GaussianAdversary
from advgame.agents.marl.marl import IPPOConfig, MAPPOConfig, TeamLearner
from advgame.agents.marl.shared import SharedIPPO
from advgame.agents.sb3.config import PPOConfig
from advgame.core.team import team_factory

SID = "MA-HalfCheetah-2x3"
NOISE = {
    "observation_adversary": GaussianAdversary(std=0.05),
    "action_adversary": GaussianAdversary(std=0.05),
}


def bench_raw(actions: np.ndarray) -> float:
    from gymnasium_robotics import mamujoco_v1

    env = mamujoco_v1.parallel_env("HalfCheetah", "2x3")
    env.reset(seed=0)
    start = time.perf_counter()
    for a in actions:
        _, _, terms, truncs, _ = env.step({"agent_0": a[:3], "agent_1": a[3:]})
        if any(terms.values()) or any(truncs.values()):
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def bench_view(actions: np.ndarray) -> float:
    view = team_factory(SID, NOISE, preset="default")()
    view.reset(seed=0)
    start = time.perf_counter()
    for a in actions:
        view.step({"agent_0": a[:3], "agent_1": a[3:]})
        if not view.agents:
            view.reset()
    return len(actions) / (time.perf_counter() - start)


def bench_learner(make: Any, steps: int) -> float:
    learner = make(steps)
    start = time.perf_counter()
    learner.learn(steps)
    fps = learner.steps / (time.perf_counter() - start)
    learner.close()
    return fps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--steps", type=int, default=4096, help="training steps per learner per round"
    )
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--n-envs", type=int, default=1, help="team views stepped in sync")
    args = parser.parse_args()
    torch.set_num_threads(1)
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, 6)).astype(np.float32)
    fns = [team_factory(SID, NOISE, preset="default") for _ in range(args.n_envs)]
    runs = {
        "raw MaMuJoCo step": lambda: bench_raw(actions),
        "team view step": lambda: bench_view(actions),
        "MAPPO train": lambda: bench_learner(
            lambda s: TeamLearner(MAPPOConfig(), fns, 0, s), args.steps
        ),
        "IPPO train": lambda: bench_learner(
            lambda s: TeamLearner(IPPOConfig(), fns, 0, s), args.steps
        ),
        "shared IPPO (SB3) train": lambda: bench_learner(
            lambda s: SharedIPPO(PPOConfig(), fns[0], 0, s, n_envs=args.n_envs), args.steps
        ),
    }
    best = dict.fromkeys(runs, 0.0)
    for r in range(args.rounds):
        for name, run in runs.items():
            best[name] = max(best[name], run())
        print(
            f"round {r + 1}/{args.rounds}: " + ", ".join(f"{k} {v:,.0f}" for k, v in best.items())
        )
    raw = best["raw MaMuJoCo step"]
    print(f"\n{SID}, {args.steps} steps x {args.rounds} rounds, {args.n_envs} view(s), best round:")
    for name, fps in best.items():
        print(f"  {name:26s} {fps:9,.0f} steps/s   {fps / raw:.3f} of raw")


if __name__ == "__main__":
    main()
