"""Speed of the ATLA alternation loop against plain SB3 PPO, measured side by side in one run.

Two ways of spending the same number of environment steps on Hopper-v5 with the same PPO
hyper-parameters (`advgame.agents.PPOConfig`: 2048 steps per rollout, 10 epochs, batch 64,
[64, 64]) and observation/reward normalization:

* ``plain``: SB3 PPO on ``gymnasium.make("Hopper-v5")`` in a `DummyVecEnv` + `VecNormalize`,
  ``model.learn(K)``.
* ``loop``: ``advgame.training.train`` with method ``atla`` (a PPO protagonist and a PPO
  observation adversary, alternating), ``protagonist_steps = adversary_steps = 2048`` and
  ``K / 4096`` iterations, so protagonist + adversary steps add up to ``K``. The per-iteration
  quick evaluation is off (``eval_episodes=0``); checkpointing, population and logs are on.

Each is timed end to end (model/side construction included) in ``--rounds`` interleaved
rounds (plain, loop, plain, loop, ...) so machine noise hits both alike; the best round of
each (and the median of the per-round ratios) is reported in environment steps per second of wall-clock time, with the ratio
loop / plain (goal >= 0.95), at each ``--n-envs`` (default 1 and 8: the loop's views run in a
`VectorView`, the frozen adversary called once per step for all views; plain SB3 runs a
`DummyVecEnv` of as many envs; each phase is one PPO rollout of all views, so at 8 envs give
``--steps 32768``). Steps per second of this process's CPU time are printed too: on a shared
machine they are the steadier measure (both run on one thread, so CPU time is the work done). The loop's own fps column (training phases only, from ``progress.csv``) is printed
as well. Torch runs on one thread in both.

Run: ``python benchmarks/bench_loop.py --steps 16384 --rounds 2 --n-envs 1,8``.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from advgame.agents import PPOConfig
from advgame.training import METHODS, TrainConfig, train

ENV = "Hopper-v5"
ROLLOUT = PPOConfig().n_steps
GOAL = 0.95


class Timer:
    """Wall-clock and CPU seconds of a block."""

    def __enter__(self) -> Timer:
        self.wall, self.cpu = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc: object) -> None:
        self.wall = time.perf_counter() - self.wall
        self.cpu = time.process_time() - self.cpu


def bench_plain(steps: int, seed: int, n_envs: int = 1) -> tuple[float, float]:
    with Timer() as t:
        learner = PPOConfig()
        fns = [lambda: gym.make(ENV)] * n_envs
        venv = VecNormalize(DummyVecEnv(fns), gamma=learner.gamma)
        model = learner.make_model(venv, seed, steps)
        model.learn(steps, progress_bar=False)
    venv.close()
    return model.num_timesteps / t.wall, model.num_timesteps / t.cpu


def bench_loop(steps: int, seed: int, out: Path, n_envs: int = 1) -> tuple[float, float, float]:
    rollout = ROLLOUT * n_envs  # one PPO rollout of every view per phase
    iterations = max(steps // (2 * rollout), 1)
    cfg = TrainConfig(
        scenario=ENV,
        **METHODS["atla"],
        iterations=iterations,
        protagonist_steps=rollout,
        adversary_steps=rollout,
        eval_episodes=0,
        seed=seed,
        n_envs=n_envs,
    )
    with Timer() as t:
        run = train(cfg, out, progress=False)
    with (run / "progress.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    done = int(rows[-1]["protagonist_steps"]) + int(rows[-1]["adversary_steps"])
    phases = sum(float(r["wall_s"]) for r in rows)
    return done / t.wall, done / t.cpu, done / phases


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=16384, help="environment steps per side")
    parser.add_argument("--rounds", type=int, default=2, help="interleaved rounds")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-envs", default="1,8", help="comma-separated n_envs to compare at")
    args = parser.parse_args()
    torch.set_num_threads(1)
    for n in (int(v) for v in args.n_envs.split(",")):
        compare(args.steps, args.rounds, args.seed, n)


def compare(steps: int, rounds: int, seed: int, n_envs: int) -> None:
    """Plain vs loop at `n_envs` views, interleaved; print the best rounds and their ratio."""
    plain: list[tuple[float, float]] = []
    loop: list[tuple[float, float]] = []
    phases: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            plain.append(bench_plain(steps, seed, n_envs))
            wall, cpu, in_phases = bench_loop(steps, seed, Path(tmp) / f"run{r}", n_envs)
            loop.append((wall, cpu))
            phases.append(in_phases)
            print(
                f"n_envs {n_envs} round {r}: plain {plain[-1][0]:.0f} steps/s (cpu "
                f"{plain[-1][1]:.0f}), loop {loop[-1][0]:.0f} steps/s (cpu {loop[-1][1]:.0f})",
                flush=True,
            )
    wall_p, cpu_p = max(w for w, _ in plain), max(c for _, c in plain)
    wall_l, cpu_l = max(w for w, _ in loop), max(c for _, c in loop)
    print(f"{ENV}, n_envs {n_envs}, {steps} environment steps each, best of {rounds} rounds:")
    print("                                wall steps/s   CPU steps/s")
    print(f"  plain SB3 PPO + VecNormalize : {wall_p:10.0f} {cpu_p:13.0f}")
    print(f"  advgame loop (atla)          : {wall_l:10.0f} {cpu_l:13.0f}")
    print(
        f"  ratio loop / plain           : {wall_l / wall_p:10.2f} {cpu_l / cpu_p:13.2f}"
        f"  (goal >= {GOAL})"
    )
    print(f"  loop training phases only    : {max(phases):10.0f}  (progress.csv wall_s)")
    ratios = [(wl / wp, cl / cp) for (wp, cp), (wl, cl) in zip(plain, loop, strict=True)]
    wall_r, cpu_r = np.median(ratios, axis=0)
    print(f"  median per-round ratio       : {wall_r:10.2f} {cpu_r:13.2f}")


if __name__ == "__main__":
    main()
