"""PPO's update with PyTorch's fused Adam beside its for-loop and foreach kernels, in one run.

On the CPU, Adam's default is a Python loop over the parameters, several small kernels each,
and a 64-wide PPO has a dozen parameter tensors updated 320 times a rollout; advgame's SB3
learners use the foreach kernel (``optimizer_kwargs={"foreach": True}``, `advgame.agents.sb3.config`:
the fused one does not mark the tensors it updates, which NumPy copies of a live learner
check), OMPO, RSC and DBC the fused one (docs/throughput.md). This builds three PPOs
with advgame's `PPOConfig` on Hopper-v5 (4 envs, one torch thread), identical but for Adam's
kernel, collects one rollout each, then times their ``train()`` (10 epochs over the rollout),
interleaved, and a whole ``learn`` of `--steps` steps for the for-loop and the fused one. The
calibration (a raw HalfCheetah-v5 step) is printed before and after.

Run: ``python benchmarks/bench_adam.py [--rounds 5] [--steps 16384]``.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from calibrate import line, step_us
from stable_baselines3.common.vec_env import DummyVecEnv

from advgame.agents import PPOConfig

KERNELS: dict[str, dict[str, Any]] = {
    "for-loop": {"foreach": False},
    "foreach": {"foreach": True},
    "fused": {"fused": True},
}


def model(kernel: str, n_steps: int) -> Any:
    """A `PPOConfig` PPO on 4 Hopper-v5 envs with Adam's `kernel`."""
    env = DummyVecEnv([lambda: gym.make("Hopper-v5")] * 4)
    ppo = PPOConfig(n_steps=n_steps).make_model(env, seed=0, total_steps=10**6)
    ppo.policy.optimizer = torch.optim.Adam(
        ppo.policy.parameters(), lr=ppo.policy.optimizer.defaults["lr"], **KERNELS[kernel]
    )
    return ppo


def main() -> None:
    """Print each kernel's ``train()`` time and the fused/for-loop ratios."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=16384, help="steps of the timed learn")
    args = ap.parse_args()
    torch.set_num_threads(1)
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))
    models = {k: model(k, 512) for k in KERNELS}
    for m in models.values():
        m.learn(2048)  # one rollout to update on
    times: dict[str, list[float]] = {k: [] for k in KERNELS}
    for _ in range(args.rounds):
        for k, m in models.items():
            began = time.perf_counter()
            m.train()
            times[k].append(time.perf_counter() - began)
    base = float(np.median(times["for-loop"]))
    for k, v in times.items():
        med = float(np.median(v))
        print(f"train() {k:8s} {med:.3f} s (median of {args.rounds}): {base / med:.2f} x for-loop")
    learn = {}
    for k in ("for-loop", "fused"):
        m = model(k, 2048)
        began = time.perf_counter()
        m.learn(args.steps)
        learn[k] = args.steps / (time.perf_counter() - began)
    print(
        f"learn({args.steps}): for-loop {learn['for-loop']:.0f} steps/s, fused "
        f"{learn['fused']:.0f} steps/s: {learn['fused'] / learn['for-loop']:.2f} x"
    )
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))


if __name__ == "__main__":
    main()
