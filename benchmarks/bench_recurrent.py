"""The LSTM protagonist's training speed beside plain PPO's, side by side in one run (issue 40).

Learners train on Hopper-v5 behind `VecNormalize` with the zoo campaign's PPO update (10 epochs
per rollout of ``--n-steps`` steps on each of ``--n-envs`` envs), in interleaved rounds of
``--steps`` environment steps each:

* ``ppo``: Stable-Baselines3's PPO with the zoo's networks (64, 64), minibatch 64;
* ``lstm b64``: `advgame.agents.RecurrentPPOConfig`'s model (sb3-contrib ``RecurrentPPO``, one
  64-unit LSTM per network read out linearly, ATLA's LSTM policy), minibatch 64;
* ``lstm bN``: the same with a minibatch of ``--big-batch`` steps (whole stretches of
  sequences per gradient step, nearer ATLA's full-batch LSTM update; fewer, longer passes);
* ``lstm bN loop``: the same config trained by sb3-contrib's own ``RecurrentPPO``, whose
  update loops in Python over the steps of every minibatch that holds an episode start (advgame
  trains `advgame.agents.recurrent.ppo.UnrolledRecurrentPPO`: one LSTM call per minibatch);
* ``lstm-sa bN``: that with the SA regulariser (`advgame.agents.SARecurrentPPOConfig`: κ 0.3,
  2 PGD steps, ε 0.075 from the first step): ATLA-LSTM-SA's protagonist.

Reported: the median steps per second of each and each one's ratio to ``ppo`` per round
(median and range), with the machine calibration (a raw HalfCheetah-v5 step) before and
after. One torch thread, as training workers run.
Run: ``python benchmarks/bench_recurrent.py [--rounds 3] [--steps 16384] [--n-envs 8]``.
Needs quiet cores: never run it beside training.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import gymnasium as gym
import torch
from _common import median_span
from calibrate import line, step_us
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from advgame.agents import PPOConfig, RecurrentPPOConfig, SARecurrentPPOConfig

ENV = "Hopper-v5"


def _model(config: Any, n_envs: int) -> Any:
    venv = VecNormalize(DummyVecEnv([lambda: gym.make(ENV)] * n_envs))
    return config.make_model(venv, seed=0, total_steps=10**7)


def _stock(config: RecurrentPPOConfig, n_envs: int) -> Any:
    """`config`'s model as sb3-contrib's own ``RecurrentPPO`` builds and trains it."""
    from sb3_contrib import RecurrentPPO

    venv = VecNormalize(DummyVecEnv([lambda: gym.make(ENV)] * n_envs))
    kwargs = config._recurrent_kwargs(venv, seed=0, total_steps=10**7, tensorboard_log=None)
    return RecurrentPPO("MlpLstmPolicy", venv, **kwargs)


def _timed(model: Any, steps: int) -> float:
    """Steps per second of `model.learn(steps)` (rollouts and updates)."""
    start = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - start)


def main() -> None:
    """Train the learners in interleaved rounds and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=16384)
    parser.add_argument("--n-envs", type=int, default=8)
    parser.add_argument("--n-steps", type=int, default=2048, help="steps per env per rollout")
    parser.add_argument("--big-batch", type=int, default=2048)
    args = parser.parse_args()
    torch.set_num_threads(1)
    before = step_us(steps=5_000, repeats=3)
    update = {"n_steps": args.n_steps, "n_epochs": 10}
    variants = {
        "ppo": _model(PPOConfig(**update), args.n_envs),
        "lstm b64": _model(RecurrentPPOConfig(**update), args.n_envs),
        f"lstm b{args.big_batch}": _model(
            RecurrentPPOConfig(**update, batch_size=args.big_batch), args.n_envs
        ),
        f"lstm b{args.big_batch} loop": _stock(
            RecurrentPPOConfig(**update, batch_size=args.big_batch), args.n_envs
        ),
        f"lstm-sa b{args.big_batch}": _model(
            SARecurrentPPOConfig(**update, batch_size=args.big_batch, sa_ramp=0.0), args.n_envs
        ),
    }
    for model in variants.values():  # warm up: imports, first rollout and update
        _timed(model, args.n_steps * args.n_envs)
    rates: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(args.rounds):
        for name, model in variants.items():
            rates[name].append(_timed(model, args.steps))
    after = step_us(steps=5_000, repeats=3)
    print(f"{ENV}, {args.n_envs} envs x {args.n_steps} steps per rollout, 10 epochs, "
          f"{args.rounds} rounds of {args.steps} steps, 1 thread")  # fmt: skip
    print(f"calibration before: {line(before, 5_000, 3)}")
    print(f"{'learner':<19} {'steps/s':>8} {'/ ppo (median, min-max)':>26}")
    for name, values in rates.items():
        span = median_span(values, rates["ppo"])
        print(f"{name:<19} {statistics.median(values):>8.0f} {span:>26}")
    print(f"calibration after: {line(after, 5_000, 3)}")


if __name__ == "__main__":
    main()
