"""Batched MuJoCo stepping: N (model, data) pairs advanced by MuJoCo's C code on a thread pool.

`ThreadedStepper` is the simulator half of a batched task (`advgame.scenarios.mujoco_batch`):
it sets each env's controls and calls ``mj_step(model, data, nstep)`` (plus
``mj_rnePostConstraint`` where the task reads contact forces), exactly the calls a Gymnasium
``MujocoEnv.do_simulation`` makes, so every env keeps its own `MjData` and evolves bit for bit
as the single env would. MuJoCo's Python bindings release the GIL inside its C functions, so the
envs of a batch split over ``threads`` Python threads step in parallel while the Python work
around them (one call per env) stays small.

Why not ``mujoco.rollout``: it steps a batch in one C call, but it restarts every row's
constraint solver from a zero (or given) ``qacc_warmstart`` and returns only the
``mjSTATE_FULLPHYSICS`` state, which does not hold the warmstart. A contact task stepped move by
move through it therefore drifts from ``gymnasium.make(id)`` in the last bits after the first
contact and, the dynamics being chaotic, visibly within an episode (measured on Hopper-v5:
1e-17 in ``qpos`` after 25 moves). It also returns no ``cfrc_ext``/``cinert``/``cvel``, which
Ant and the Humanoids observe. `benchmarks/bench_batch_physics.py` measures both paths side
by side.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from advgame.errors import ConfigError

__all__ = ["THREADS_VAR", "ThreadedStepper", "default_threads", "shared_stepper"]

THREADS_VAR = "ADVGAME_PHYSICS_THREADS"
"""Environment variable that caps the simulator threads of batched steps (pool workers set 1)."""


def default_threads() -> int:
    """Simulator threads by default: `THREADS_VAR` if set, else the cores this process may use."""
    value = os.environ.get(THREADS_VAR, "").strip()
    if value:
        if not value.isdigit() or int(value) < 1:
            raise ConfigError(f"{THREADS_VAR} must be a positive integer; got {value!r}.")
        return int(value)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not every platform has affinity
        return max(1, os.cpu_count() or 1)


class ThreadedStepper:
    """Advance MuJoCo simulations `nstep` substeps each, split over `threads` threads.

    A batch is split over the threads only when it is worth it: each kind of model's cost per
    env step is measured on the calling thread (its first `PROBES` steps, then one step in
    every `REPROBE`, and every step that stays there), the cheapest step seen is its cost, and a
    step whose envs would take less than `MIN_BATCH_SECONDS` on one thread stays there. The
    cheapest, not the latest: a first step (imports, cold caches) or a step preempted by another
    process takes longer, never less, and one such step must not send every later step of a
    small batch to a second thread (it did: on a busy 2-core machine the first Walker2d step
    measured 100 µs per env, so four envs were split for the rest of the run).

    Args:
        threads: simulator threads (``None``: `default_threads`), the calling thread included:
            it steps the first share of the envs while ``threads - 1`` pool threads step the
            rest. With 1 every env is stepped on the calling thread.

    Example:
        >>> import gymnasium as gym, numpy as np
        >>> envs = [gym.make("Hopper-v5").unwrapped for _ in range(2)]
        >>> stepper = ThreadedStepper(threads=1)
        >>> stepper.step(envs, np.zeros((2, 3)), nstep=4)
        >>> stepper.close()

    """

    MIN_BATCH_SECONDS = 300e-6
    """A step uses more than one thread only when its envs would take at least this long on one.

    Handing work to a second thread and collecting it costs about 100 µs per step on the 2-core
    VM this was measured on (`benchmarks/bench_batch_physics.py`: two threads lose to one at
    8 HalfCheetah copies, about 200 µs of simulation, and win at 8 Hopper copies, about 400).
    """

    PROBES = 8
    """Steps of each kind of model measured on the calling thread before any is split."""

    REPROBE = 512
    """A split kind is measured on the calling thread again once in this many steps."""

    def __init__(self, threads: int | None = None) -> None:
        if threads is None:
            threads = default_threads()
        if not isinstance(threads, int) or isinstance(threads, bool) or threads < 1:
            raise ConfigError(f"threads must be a positive integer; got {threads!r}.")
        self.threads = threads
        """The most threads a step uses (a step of fewer envs, or of cheap ones, uses fewer)."""
        self._pool: ThreadPoolExecutor | None = None
        self._pid = os.getpid()
        self._cost: dict[tuple[int, ...], float] = {}  # cheapest seconds per env step, one thread
        self._calls: dict[tuple[int, ...], int] = {}  # steps of each kind so far

    def step(
        self,
        owners: Sequence[Any],
        ctrl: np.ndarray,
        nstep: int,
        post_constraint: bool = True,
    ) -> None:
        """Set ``ctrl[k]`` as the controls of ``owners[k]`` and step each `nstep` substeps.

        Args:
            owners: objects with live ``model`` and ``data`` attributes (Gymnasium
                ``MujocoEnv`` objects); read at every step, so a model a dynamics disruptor swapped
                in is the one stepped.
            ctrl: ``[len(owners), nu]`` controls.
            nstep: substeps per env (the task's ``frame_skip``).
            post_constraint: also call ``mj_rnePostConstraint`` after the substeps (Gymnasium
                does, and ``cfrc_ext`` needs it); the state does not depend on it.

        """
        n = len(owners)
        parts = min(self.threads, n)
        if parts < 2:
            self._run(owners, ctrl, nstep, post_constraint, 0, n)
            return
        model = owners[0].model
        key = (model.nq, model.nv, model.nbody, model.ngeom, model.nu, nstep)
        cost, calls = self._cost.get(key), self._calls.get(key, 0)
        self._calls[key] = calls + 1
        if (
            cost is None
            or calls < self.PROBES
            or calls % self.REPROBE == 0
            or cost * n < self.MIN_BATCH_SECONDS
        ):  # measure, on this thread
            start = time.perf_counter()
            self._run(owners, ctrl, nstep, post_constraint, 0, n)
            seen = (time.perf_counter() - start) / n
            self._cost[key] = seen if cost is None else min(cost, seen)
            return
        if self._pool is None or self._pid != os.getpid():  # a forked child has no threads
            self._pid = os.getpid()
            self._pool = ThreadPoolExecutor(self.threads - 1, thread_name_prefix="advgame-physics")
        bounds = [int(b) for b in np.linspace(0, n, parts + 1)]
        futures = [
            self._pool.submit(self._run, owners, ctrl, nstep, post_constraint, lo, hi)
            for lo, hi in itertools.pairwise(bounds[1:])
        ]
        self._run(owners, ctrl, nstep, post_constraint, 0, bounds[1])  # the caller's share
        for future in futures:
            future.result()

    @staticmethod
    def _run(
        owners: Sequence[Any], ctrl: np.ndarray, nstep: int, post: bool, lo: int, hi: int
    ) -> None:
        import mujoco

        step, post_constraint = mujoco.mj_step, mujoco.mj_rnePostConstraint
        for k in range(lo, hi):
            owner = owners[k]
            model, data = owner.model, owner.data
            data.ctrl[:] = ctrl[k]
            step(model, data, nstep)
            if post:
                post_constraint(model, data)

    def close(self) -> None:
        """Stop the threads (idempotent; a later step starts them again)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


_SHARED: dict[int, ThreadedStepper] = {}


def shared_stepper(threads: int | None = None) -> ThreadedStepper:
    """The process's stepper with `threads` threads (``None``: `default_threads`), made once."""
    n = default_threads() if threads is None else threads
    if n not in _SHARED:
        _SHARED[n] = ThreadedStepper(n)
    return _SHARED[n]
