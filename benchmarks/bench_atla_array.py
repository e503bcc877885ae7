"""One ATLA iteration on Hopper-v5 with its views on the array game vs on the lockstep path.

A campaign-sized ATLA iteration (`advgame.training.METHODS["atla"]`: a PPO protagonist and a
PPO observation adversary in normalized units, alternating; ``protagonist_steps`` and
``adversary_steps`` one PPO rollout of all ``--n-envs`` views each, default 8 views, so
16,384 steps per side) is timed end to end (sides built, both phases trained, checkpoint
written; the quick evaluation off), ``--rounds`` times each way, interleaved:

* ``array``: the training views' `VectorView` plays them as one `ArrayGame` (today's default);
* ``lockstep``: the same views on `VectorView`'s lockstep path (``array=False``: before).

With ``--timers`` the second way is instead the array path with MuJoCo's profiling timers kept
on (``ADVGAME_MUJOCO_TIMERS=1``, as before the games switched them off:
`advgame.core.mujoco_timers`), and the ratio printed is array / array with timers.

Each round runs both, in alternating order (the second way first in even rounds).

Printed: a calibration line (`benchmarks/calibrate.py`), each round's environment steps per
second both ways, and the median per-round ratio array / lockstep (or / array with timers).
Torch runs on one thread.
Run on quiet cores: ``python benchmarks/bench_atla_array.py`` (``--n-envs``, ``--rounds``).
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import torch
from calibrate import step_us

import advgame.core.vector as vector
from advgame.agents import PPOConfig
from advgame.core.mujoco_timers import TIMERS_VAR
from advgame.training import METHODS, TrainConfig, train

ENV = "Hopper-v5"
_INIT = vector.VectorView.__init__


def _force(array: bool) -> None:
    """Make every `VectorView` built from now on take the array path or not."""

    def init(self: Any, env_fns: Any, exact: bool = True, array_: bool = array) -> None:
        _INIT(self, env_fns, exact, array=array_)

    vector.VectorView.__init__ = init  # type: ignore[method-assign,assignment]


def iteration(out: Path, n_envs: int, seed: int, array: bool, timers: bool = False) -> float:
    """Environment steps per second of one ATLA iteration (both phases, end to end)."""
    _force(array)
    if timers:  # the bindings set MuJoCo's timers with the iteration's new MjData; kept on
        os.environ[TIMERS_VAR] = "1"
    else:
        os.environ.pop(TIMERS_VAR, None)
    rollout = PPOConfig().n_steps * n_envs
    cfg = TrainConfig(
        scenario=ENV,
        **METHODS["atla"],
        iterations=1,
        protagonist_steps=rollout,
        adversary_steps=rollout,
        eval_episodes=0,
        seed=seed,
        n_envs=n_envs,
    )
    start = time.perf_counter()
    run = train(cfg, out, progress=False)
    wall = time.perf_counter() - start
    os.environ.pop(TIMERS_VAR, None)
    with (run / "progress.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    return (int(rows[-1]["protagonist_steps"]) + int(rows[-1]["adversary_steps"])) / wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n-envs", type=int, default=8)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--timers",
        action="store_true",
        help="compare the array path with MuJoCo's profiling timers on, not the lockstep path",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    load = os.getloadavg()[0]
    print(f"calibration: raw HalfCheetah-v5 step {step_us(5_000, 3):.1f} µs (load {load:.2f})")
    ratios = []
    other = "array with timers" if args.timers else "lockstep"
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            # the order alternates by round (ABBA...), so that drift within a round, or what the
            # first iteration leaves behind for the second, does not favour one path
            rates = {}
            for today in (False, True) if r % 2 == 0 else (True, False):
                array, timers = today or args.timers, not today and args.timers
                path = Path(tmp) / f"{'array' if today else 'other'}{r}"
                rates[today] = iteration(path, args.n_envs, args.seed, array, timers)
            base, arr = rates[False], rates[True]
            ratios.append(arr / base)
            print(f"round {r}: {other} {base:.0f} steps/s, array {arr:.0f} steps/s", flush=True)
    print(
        f"{ENV} ATLA iteration, {args.n_envs} views: median ratio array / {other} "
        f"{statistics.median(ratios):.2f} (rounds: {', '.join(f'{x:.2f}' for x in ratios)})"
    )


if __name__ == "__main__":
    main()
