"""One ATLA-LSTM iteration with the frozen LSTM opponents batched beside asked copy by copy.

In ATLA-LSTM both sides are LSTMs: while the protagonist learns, the frozen adversary acts in
each of the ``--n-envs`` training views, and the other way round. `VectorView` asks those copies
one at a time when it must keep every episode bit for bit a single view's (``exact=True``:
torch's batched LSTM pass rounds differently from its one-row pass); the training loop builds
its views with ``exact=False``, so the copies share one forward pass (`act_batch`). This times
one iteration of ``--steps`` protagonist and ``--steps`` adversary steps on Hopper-v5 both ways,
in interleaved rounds (each a fresh run of `advgame.training.train` with the zoo campaign's
LSTM settings: minibatch 1,024, 10 epochs), and prints the median wall time of each and the
ratio per round (median and range), with the machine calibration (a raw HalfCheetah-v5 step)
before and after. One torch thread, as training workers run.
Run: ``python benchmarks/bench_atla_lstm.py [--rounds 3] [--steps 16384] [--n-envs 8]``.
Needs quiet cores: never run it beside training.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import torch
from _common import median_span
from calibrate import line, step_us

from advgame.agents import side
from advgame.core.vector import VectorView
from advgame.training import METHODS, TrainConfig, train


def _iteration(steps: int, n_envs: int, exact: bool) -> float:
    """Wall seconds of one ATLA-LSTM iteration (a fresh run), opponents batched unless `exact`."""
    made = side._make_venv
    if exact:  # the views as a bit-for-bit equivalence check would build them
        side._make_venv = lambda fns, vec_env: VectorView(list(fns), exact=True)  # type: ignore[assignment]
    hparams = {"n_steps": steps // n_envs, "batch_size": 1024}
    config = TrainConfig(
        **{**METHODS["atla-lstm"], "scenario": "Hopper-v5", "iterations": 1, "n_envs": n_envs},
        protagonist_steps=steps,
        adversary_steps=steps,
        protagonist_hparams=hparams,
        adversary_hparams=hparams,
        eval_episodes=0,
    )
    try:
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            train(config, Path(folder) / "run", progress=False)
            return time.perf_counter() - start
    finally:
        side._make_venv = made


def main() -> None:
    """Time the iteration both ways in interleaved rounds and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=16384, help="steps of each side")
    parser.add_argument("--n-envs", type=int, default=8)
    args = parser.parse_args()
    torch.set_num_threads(1)
    before = step_us(steps=5_000, repeats=3)
    _iteration(args.n_envs * 64, args.n_envs, exact=False)  # warm up: imports, first builds
    times: dict[str, list[float]] = {"copy by copy": [], "batched": []}
    for _ in range(args.rounds):
        times["copy by copy"].append(_iteration(args.steps, args.n_envs, exact=True))
        times["batched"].append(_iteration(args.steps, args.n_envs, exact=False))
    after = step_us(steps=5_000, repeats=3)
    print(f"ATLA-LSTM on Hopper-v5: one iteration of {args.steps} + {args.steps} steps, "
          f"{args.n_envs} envs, minibatch 1024, {args.rounds} rounds, 1 thread")  # fmt: skip
    print(f"calibration before: {line(before, 5_000, 3)}")
    print(f"{'LSTM opponents':<14} {'s/iteration':>12} {'/ copy by copy (median, min-max)':>34}")
    for name, values in times.items():
        span = median_span(values, times["copy by copy"])
        print(f"{name:<14} {statistics.median(values):>12.1f} {span:>34}")
    print(f"calibration after: {line(after, 5_000, 3)}")


if __name__ == "__main__":
    main()
