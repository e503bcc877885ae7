"""SA-PPO's training speed beside plain PPO's, side by side in one run (issue 21: report the ratio).

Three learners train on Hopper-v5 with ATLA's PPO update (2,048 steps per update over
``--n-envs`` envs behind `VecNormalize`, minibatch 64, 10 epochs), in interleaved rounds of
``--steps`` environment steps each:

* ``ppo``: Stable-Baselines3's PPO;
* ``sa-ppo``: `advgame.agents.sa_ppo.SAPPO` (κ 0.1, ε 0.075 from the first step, 10 PGD steps
  per minibatch), its inner maximisation through the NumPy copy of the actor;
* ``sa-ppo torch``: the same with the inner maximisation through torch's autograd (the path
  before the NumPy walk, and the one other policies take).

Reported: the median steps per second of each, and each one's ratio to ``ppo`` per round
(median and range). One torch thread, as training workers run.
Run: ``python benchmarks/bench_sa_ppo.py [--rounds 3] [--steps 8192] [--n-envs 1]``.
Needs quiet cores: never run it beside training.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from advgame.agents import sa_ppo
from advgame.agents.sa_ppo import SAPPO

ENV = "Hopper-v5"


def _model(kind: str, n_envs: int) -> Any:
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(ENV)] * n_envs))
    common = {"n_steps": 2048 // n_envs, "batch_size": 64, "n_epochs": 10, "seed": 0}
    if kind == "ppo":
        return PPO("MlpPolicy", venv, device="cpu", **common)
    return SAPPO("MlpPolicy", venv, device="cpu", sa_kappa=0.1, sa_eps=0.075, sa_ramp=0.0, **common)


def _timed(model: Any, steps: int, walk: Callable[..., Any] | None) -> float:
    """Steps per second of `model.learn(steps)`; `walk` replaces SA-PPO's NumPy walk if given."""
    saved = sa_ppo._numpy_walk
    if walk is not None:
        sa_ppo._numpy_walk = walk
    try:
        start = time.perf_counter()
        model.learn(steps, reset_num_timesteps=False)
        return steps / (time.perf_counter() - start)
    finally:
        sa_ppo._numpy_walk = saved


def main() -> None:
    """Train the three learners in interleaved rounds and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=8192)
    parser.add_argument("--n-envs", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(1)

    def torch_walk(*_: Any) -> None:
        return None

    variants: dict[str, tuple[Any, Callable[..., Any] | None]] = {
        "ppo": (_model("ppo", args.n_envs), None),
        "sa-ppo": (_model("sa-ppo", args.n_envs), None),
        "sa-ppo torch": (_model("sa-ppo", args.n_envs), torch_walk),
    }
    for model, walk in variants.values():  # warm up: imports, first rollout
        _timed(model, 2048, walk)
    rates: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(args.rounds):
        for name, (model, walk) in variants.items():
            rates[name].append(_timed(model, args.steps, walk))
    print(f"{ENV}, n_envs {args.n_envs}, {args.rounds} rounds of {args.steps} steps, 1 thread")
    print(f"{'learner':<14} {'steps/s':>8} {'/ ppo (median, min-max)':>26}")
    for name, values in rates.items():
        ratios = [v / p for v, p in zip(values, rates["ppo"], strict=True)]
        span = f"{statistics.median(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f})"
        print(f"{name:<14} {statistics.median(values):>8.0f} {span:>26}")


if __name__ == "__main__":
    main()
