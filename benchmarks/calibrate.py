"""The machine's speed today: the mean wall time of one raw HalfCheetah-v5 step, in µs.

Times quoted in the docs (the demo, the test suite) depend on how fast the machine is at the
moment; on a shared machine that drifts by tens of percent within minutes. Print this number
beside a timing so that a reader can scale it to their own machine: the README's times are for
a day when this prints about 35 µs.

Steps ``gymnasium.make("HalfCheetah-v5")`` (its default wrappers) with seeded uniform random
actions drawn before timing, resetting at episode ends; after a warm-up, ``--repeats`` runs of
``--steps`` steps each, and reports the median of their per-step means, with the one-minute
load average when it started: the step time is one core's speed, so other jobs competing for
the cores (which slow a suite run on every core) show in the load, not in the µs. It needs
Gymnasium's MuJoCo tasks only, not advgame, so that a half-moved checkout still calibrates.
Run: ``python benchmarks/calibrate.py`` (``--steps``, ``--repeats``, ``--json``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from typing import cast

import gymnasium as gym
import numpy as np

ENV_ID = "HalfCheetah-v5"


def step_us(steps: int = 20_000, repeats: int = 5, warmup: int = 1_000, seed: int = 0) -> float:
    """Median over `repeats` runs of the mean wall µs of a raw `ENV_ID` step (`steps` a run)."""
    env = gym.make(ENV_ID)
    env.reset(seed=seed)
    space = cast(gym.spaces.Box, env.action_space)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(space.low, space.high, (warmup + steps, *space.shape)).astype(space.dtype)
    step_through(env, actions[:warmup])
    means = [step_through(env, actions[warmup:]) / steps * 1e6 for _ in range(repeats)]
    env.close()
    return statistics.median(means)


def step_through(env: gym.Env, actions: np.ndarray) -> float:
    """Wall seconds of stepping `env` with each of `actions`, resetting at episode ends.

    The benchmarks' one stepping loop (`_common` re-exports it); it lives here because this
    script must run without advgame.
    """
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return time.perf_counter() - start


def line(us: float, steps: int, repeats: int, load: float | None = None) -> str:
    """The one line that reports a calibration (and the load average it started at)."""
    busy = "" if load is None else f"; load {load:.1f} on {os.cpu_count()} cores"
    return (
        f"calibration: {ENV_ID} raw step {us:.1f} µs (median of {repeats} × {steps:,} steps{busy})"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="steps per repeat")
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats (median reported)")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of a line")
    args = parser.parse_args(argv)
    load = os.getloadavg()[0]
    us = step_us(args.steps, args.repeats)
    if args.json:
        record = {"env": ENV_ID, "step_us": round(us, 2), "steps": args.steps}
        print(json.dumps({**record, "repeats": args.repeats, "load": round(load, 2)}))
    else:
        print(line(us, args.steps, args.repeats, load))


if __name__ == "__main__":
    main()
