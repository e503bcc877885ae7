"""SA-PPO's training speed beside plain PPO's, side by side in one run (issue 21: report the ratio).

Five learners train on Hopper-v5 with ATLA's PPO update (2,048 steps per update over
``--n-envs`` envs behind `VecNormalize`, minibatch 64, 10 epochs), in interleaved rounds of
``--steps`` environment steps each:

* ``ppo``: Stable-Baselines3's PPO;
* ``sa-ppo``: `advgame.agents.sa.ppo.SAPPO` (κ 0.1, ε 0.075 from the first step, 10 PGD steps
  per minibatch), its inner maximisation through the NumPy copy of the actor;
* ``sa-ppo torch``: the same with the inner maximisation through torch's autograd (the path
  before the NumPy walk, and the one other policies take);
* ``recurrent-ppo``: sb3-contrib's RecurrentPPO (``MlpLstmPolicy``: 256-unit LSTMs before the
  actor's and the critic's [64, 64]), the ATLA-LSTM learner;
* ``sa-recurrent-ppo``: `advgame.agents.sa.recurrent.SARecurrentPPO`, the same with the
  sequence regulariser of ATLA-LSTM-SA (κ 0.3, ε 0.075 from the first step, 2 PGD steps).

Reported: the median steps per second of each, and each one's ratio per round (median and
range) to its baseline: ``ppo`` for the feed-forward learners, ``recurrent-ppo`` for the LSTM
ones. One torch thread, as training workers run. ``--learners`` picks a subset (a baseline is
added where its learner needs it).
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
from sb3_contrib import RecurrentPPO
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from advgame.agents import sa_ppo
from advgame.agents.sa.ppo import SAPPO
from advgame.agents.sa.recurrent import SARecurrentPPO

ENV = "Hopper-v5"
BASELINE = {"ppo": "ppo", "sa-ppo": "ppo", "sa-ppo torch": "ppo",
            "recurrent-ppo": "recurrent-ppo", "sa-recurrent-ppo": "recurrent-ppo"}  # fmt: skip
"""Each learner, and the learner its ratio is taken to."""


def _model(kind: str, n_envs: int) -> Any:
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(ENV)] * n_envs))
    common: dict[str, Any] = {
        "n_steps": 2048 // n_envs,
        "batch_size": 64,
        "n_epochs": 10,
        "seed": 0,
    }
    sa: dict[str, Any] = {"sa_eps": 0.075, "sa_ramp": 0.0}
    if kind == "ppo":
        return PPO("MlpPolicy", venv, device="cpu", **common)
    if kind == "recurrent-ppo":
        return RecurrentPPO("MlpLstmPolicy", venv, device="cpu", **common)
    if kind == "sa-recurrent-ppo":
        return SARecurrentPPO(
            "MlpLstmPolicy", venv, device="cpu", sa_kappa=0.3, sa_steps=2, **sa, **common
        )
    return SAPPO("MlpPolicy", venv, device="cpu", sa_kappa=0.1, **sa, **common)


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
    parser.add_argument("--learners", nargs="+", choices=list(BASELINE), default=list(BASELINE))
    args = parser.parse_args()
    torch.set_num_threads(1)

    def torch_walk(*_: Any) -> None:
        return None

    names = [n for n in BASELINE if n in args.learners or n in {BASELINE[m] for m in args.learners}]
    variants: dict[str, tuple[Any, Callable[..., Any] | None]] = {
        name: (
            _model(name.removesuffix(" torch"), args.n_envs),
            torch_walk if name.endswith(" torch") else None,
        )
        for name in names
    }
    for model, walk in variants.values():  # warm up: imports, first rollout
        _timed(model, 2048, walk)
    rates: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(args.rounds):
        for name, (model, walk) in variants.items():
            rates[name].append(_timed(model, args.steps, walk))
    print(f"{ENV}, n_envs {args.n_envs}, {args.rounds} rounds of {args.steps} steps, 1 thread")
    print(f"{'learner':<17} {'steps/s':>8} {'/ baseline (median, min-max)':>29}  baseline")
    for name, values in rates.items():
        base = BASELINE[name]
        ratios = [v / p for v, p in zip(values, rates[base], strict=True)]
        span = f"{statistics.median(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f})"
        print(f"{name:<17} {statistics.median(values):>8.0f} {span:>29}  {base}")


if __name__ == "__main__":
    main()
