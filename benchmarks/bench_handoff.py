"""How a batched step hands its envs to a second thread: the stepper's relay against a pool.

Two ways of splitting the simulator's share of an `ArrayGame` step (HalfCheetah-v5, preset
``default``, random protagonist and adversary actions drawn before timing) over two threads,
both on the compiled stepping loop:

* ``pool``: the design before 7 Dec: equal shares, the helper's share submitted to a
  `concurrent.futures.ThreadPoolExecutor` and collected with ``Future.result()``.
* ``relay``: `ThreadedStepper` as it is: a persistent helper parked on a lock
  (`advgame.core.relay.Relay`), envs taken a chunk at a time by whichever thread is free, and
  the caller polling a helper still at work for about one chunk before it sleeps.

The same game is stepped in rounds of ``--steps`` steps, ``pool`` and ``relay`` in turns (the
order alternating by round); printed is the median (quartiles) of the per-round time ratio
relay / pool at each N, with a calibration line. Run on quiet cores:
``python benchmarks/bench_handoff.py`` (``--n``, ``--rounds``, ``--steps``).
"""

from __future__ import annotations

import argparse
import itertools
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from _common import quartiles
from bench_array_game import _Array, _calibrate

from advgame.core.native_step import native_loop
from advgame.core.physics import Gathered, ThreadedStepper


class _PoolStepper(ThreadedStepper):
    """The split before the relay: equal shares, the helper's on a thread pool."""

    def __init__(self, threads: int) -> None:
        super().__init__(threads)
        self._executor = ThreadPoolExecutor(threads - 1)

    def step(  # type: ignore[override]
        self,
        owners: Any,
        ctrl: np.ndarray,
        nstep: int,
        post_constraint: bool = True,
        before: Any = (),
        after: Any = (),
    ) -> Gathered:
        pointers = self._pointers.get(owners)
        native = self._native(native_loop(), pointers, ctrl, nstep, post_constraint, before, after)
        if native is None:
            raise SystemExit("bench_handoff needs the compiled loop (numba).")
        run, rows = native
        n, parts = len(owners), self.threads
        bounds = [n * i // parts for i in range(parts + 1)]
        futures = [self._executor.submit(run, lo, hi) for lo, hi in itertools.pairwise(bounds[1:])]
        run(0, bounds[1])
        for future in futures:
            future.result()
        return Gathered(*rows, pointers.timesteps())


def measure(n: int, rounds: int, steps: int) -> list[float]:
    """Per-round time ratios relay / pool of one array game of `n` copies on two threads."""
    import advgame.scenarios.mujoco_batch as batch

    game = _Array("HalfCheetah-v5", n, 2)
    relay, pool = batch.shared_stepper(2), _PoolStepper(2)
    steppers = {"relay": lambda threads=None: relay, "pool": lambda threads=None: pool}
    game.reset(0)
    actions = np.random.default_rng(0).uniform(-1, 1, (50, n, 6)).astype(np.float32)
    times: dict[str, list[float]] = {"relay": [], "pool": []}
    kept = batch.shared_stepper
    try:
        for r in range(rounds + 1):  # round 0 warms both up (probes, compilation), dropped
            for name in ("pool", "relay") if r % 2 else ("relay", "pool"):
                batch.shared_stepper = steppers[name]  # what the batched task steps with
                start = time.perf_counter()
                for i in range(steps):
                    game.step(actions[i % len(actions)])
                if r:
                    times[name].append(time.perf_counter() - start)
    finally:
        batch.shared_stepper = kept
        pool.close()
        game.close()
    return [a / b for a, b in zip(times["relay"], times["pool"], strict=True)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", default="8,64")
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--steps", type=int, default=0, help="steps a round (0: 4,000 / N)")
    args = parser.parse_args()
    _calibrate("wall")
    for n in (int(x) for x in args.n.split(",")):
        ratios = measure(n, args.rounds, args.steps or max(20, 4000 // n))
        print(f"N = {n}, two threads: time relay / pool per round {quartiles(ratios)}")
    _calibrate("wall")


if __name__ == "__main__":
    main()
