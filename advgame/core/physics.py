"""Batched MuJoCo stepping: N (model, data) pairs advanced by MuJoCo's C code on threads.

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

Where numba is installed, each thread runs its share of the loop as one compiled call that holds
no GIL (`advgame.core.native_step`): the same C calls, so the same bits, without a GIL hand-off
per env.
"""

from __future__ import annotations

import functools
import itertools
import math
import os
import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from advgame.core.mujoco_timers import quiet_timers
from advgame.core.native_step import BatchPointers, PointerCache, native_loop
from advgame.core.relay import Relay
from advgame.errors import ConfigError

__all__ = ["THREADS_VAR", "Gathered", "ThreadedStepper", "default_threads", "shared_stepper"]

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


class Gathered(NamedTuple):
    """The ``MjData`` fields a `ThreadedStepper.step` read from each env as it stepped them.

    Attributes:
        before: ``{field: [N, ...]}``, row ``k`` read from env ``k`` just before its substeps.
        after: the same, read just after them (and ``mj_rnePostConstraint``).
        timestep: float64 ``[N]``, each env's ``model.opt.timestep`` in this step.

    """

    before: dict[str, np.ndarray]
    after: dict[str, np.ndarray]
    timestep: np.ndarray


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
            it and ``threads - 1`` helper threads (`advgame.core.relay.Relay`) take the envs a
            chunk at a time (`CHUNK_SECONDS`). With 1 every env is stepped on the calling
            thread.
        native: step each thread's share as one compiled call that holds no GIL, where it can
            be built (`advgame.core.native_step`: the same C calls, the same bits); ``False``
            keeps the bindings' Python loop.

    Example:
        >>> import gymnasium as gym, numpy as np
        >>> envs = [gym.make("Hopper-v5").unwrapped for _ in range(2)]
        >>> stepper = ThreadedStepper(threads=1)
        >>> got = stepper.step(envs, np.zeros((2, 3)), nstep=4, after=("qpos",))
        >>> got.after["qpos"].shape
        (2, 6)
        >>> stepper.close()

    """

    MIN_BATCH_SECONDS = 200e-6
    """A step uses more than one thread only when its envs would take at least this long on one.

    Handing work to a second thread and collecting it cost about 100 µs per step on the 2-core
    VM this was measured on with a thread pool, about half that with the `Relay` (7 Dec, two
    threads against one, physics alone: 2 and 4 HalfCheetah copies, 73 and 138 µs on one
    thread, 0.74 and 0.79 as fast; 2 Hopper copies, 197 µs, 1.11; 8 HalfCheetah, 269 µs, 1.27).
    """

    PROBES = 8
    """Steps of each kind of model measured on the calling thread before any is split."""

    REPROBE = 512
    """A split kind is measured on the calling thread again once in this many steps."""

    CHUNK_SECONDS = 100e-6
    """The threads of a split step take its envs in chunks of about this long on one thread.

    Whichever thread is free takes the next chunk, so a thread the machine slows down steps
    fewer envs instead of keeping the others waiting for its fixed share; the caller then polls
    a helper still at work for about one chunk before it sleeps (`Relay.run`'s ``spin``).
    Which thread steps which env changes no result: each env has its own `MjData`.
    """

    def __init__(self, threads: int | None = None, native: bool = True) -> None:
        if threads is None:
            threads = default_threads()
        if not isinstance(threads, int) or isinstance(threads, bool) or threads < 1:
            raise ConfigError(f"threads must be a positive integer; got {threads!r}.")
        self.threads = threads
        """The most threads a step uses (a step of fewer envs, or of cheap ones, uses fewer)."""
        self.native = native
        """Whether steps use the compiled loop where it can be built."""
        self._relay = Relay(threads - 1)
        self._cost: dict[tuple[int, ...], float] = {}  # cheapest seconds per env step, one thread
        self._calls: dict[tuple[int, ...], int] = {}  # steps of each kind so far
        self._pointers = PointerCache()

    def step(
        self,
        owners: Sequence[Any],
        ctrl: np.ndarray,
        nstep: int,
        post_constraint: bool = True,
        before: Sequence[str] = (),
        after: Sequence[str] = (),
    ) -> Gathered:
        """Set ``ctrl[k]`` as the controls of ``owners[k]`` and step each `nstep` substeps.

        Args:
            owners: objects with live ``model`` and ``data`` attributes (Gymnasium
                ``MujocoEnv`` objects); read at every step, so a model a dynamics disruptor swapped
                in is the one stepped.
            ctrl: ``[len(owners), nu]`` controls.
            nstep: substeps per env (the task's ``frame_skip``).
            post_constraint: also call ``mj_rnePostConstraint`` after the substeps (Gymnasium
                does, and ``cfrc_ext`` needs it); the state does not depend on it.
            before: ``MjData`` fields to read from each env just before its substeps.
            after: ``MjData`` fields to read from each env just after them.

        Returns:
            the fields read, ``[N, ...]`` each, row ``k`` from ``owners[k]`` (`Gathered`): read
            in the stepping loop, env by env, so that on the compiled loop reading them costs
            no Python per env; and each env's timestep.

        """
        n = len(owners)
        if not n:
            return Gathered({}, {}, np.zeros(0))
        quiet_timers()  # MuJoCo's profiling clocks: about a tenth of a substep (mujoco_timers)
        pointers = self._pointers.get(owners)
        timestep = pointers.timesteps()
        loop = native_loop() if self.native else None
        native = self._native(loop, pointers, ctrl, nstep, post_constraint, before, after)
        run: Callable[[int, int], None]
        if native is None:  # the bindings' loop
            gathered = _allocate(owners, before, after, timestep)
            run = functools.partial(self._run, owners, ctrl, nstep, post_constraint, gathered)
        else:
            run, rows = native
            gathered = Gathered(*rows, timestep)
        parts = min(self.threads, n)
        if parts < 2:
            run(0, n)
            return gathered
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
            run(0, n)
            seen = (time.perf_counter() - start) / n
            self._cost[key] = seen if cost is None else min(cost, seen)
            return gathered
        # rows in chunks of about CHUNK_SECONDS, taken in turn by whichever thread is free
        # (next() of one shared counter is atomic under the GIL): a thread the machine slows
        # takes fewer chunks instead of making the others wait for its fixed share
        size = max(1, min(math.ceil(self.CHUNK_SECONDS / cost), -(-n // parts)))
        starts = itertools.count(0, size)

        def share() -> None:
            for lo in starts:
                if lo >= n:
                    return
                run(lo, min(lo + size, n))

        # the caller polls a helper still at work for about one chunk before sleeping
        if not self._relay.run([share] * (parts - 1), share, spin=size * cost):
            run(0, n)  # another thread is stepping a batch on the helpers: this one alone
        return gathered

    def _native(
        self,
        loop: Callable[..., None] | None,
        pointers: BatchPointers,
        ctrl: np.ndarray,
        nstep: int,
        post: bool,
        before: Sequence[str],
        after: Sequence[str],
    ) -> tuple[Callable[[int, int], None], tuple[dict, dict]] | None:
        """The compiled `loop` bound to this batch (``run(lo, hi)``) and the rows it fills.

        ``None`` where it cannot step the batch (no loop, controls of differing sizes, a field
        that is not plain float64): the bindings' loop does then.
        """
        if loop is None:
            return None
        src = np.ascontiguousarray(ctrl, dtype=np.float64)
        first, second = pointers.layout(tuple(before)), pointers.layout(tuple(after))
        if src.shape != (len(pointers.pairs), pointers.nu) or first is None or second is None:
            return None
        (pre, early), (late, rows) = first.arguments(), second.arguments()
        fields = dict(zip(before, early, strict=True)), dict(zip(after, rows, strict=True))
        p = pointers
        run = functools.partial(loop, p.models, p.datas, p.ctrls, src, p.nu, nstep, post)
        return lambda lo, hi: run(lo, hi, pre, late), fields

    @staticmethod
    def _run(
        owners: Sequence[Any],
        ctrl: np.ndarray,
        nstep: int,
        post: bool,
        gathered: Gathered,
        lo: int,
        hi: int,
    ) -> None:
        import mujoco

        step, post_constraint = mujoco.mj_step, mujoco.mj_rnePostConstraint
        before, after = tuple(gathered.before.items()), tuple(gathered.after.items())
        for k in range(lo, hi):
            owner = owners[k]
            model, data = owner.model, owner.data
            for name, out in before:
                out[k] = getattr(data, name)
            data.ctrl[:] = ctrl[k]
            step(model, data, nstep)
            if post:
                post_constraint(model, data)
            for name, out in after:
                out[k] = getattr(data, name)

    def close(self) -> None:
        """Stop the threads (idempotent; a later step starts them again)."""
        self._relay.close()


def _allocate(
    owners: Sequence[Any], before: Sequence[str], after: Sequence[str], timestep: np.ndarray
) -> Gathered:
    """Empty ``[N, ...]`` rows for the fields the bindings' loop reads, shaped as env 0's."""

    def rows(names: Sequence[str]) -> dict[str, np.ndarray]:
        out = {}
        for name in names:
            field = np.asarray(getattr(owners[0].data, name))
            out[name] = np.empty((len(owners), *field.shape), field.dtype)
        return out

    return Gathered(rows(before), rows(after), timestep)


_SHARED: dict[int, ThreadedStepper] = {}


def shared_stepper(threads: int | None = None) -> ThreadedStepper:
    """The process's stepper with `threads` threads (``None``: `default_threads`), made once."""
    n = default_threads() if threads is None else threads
    if n not in _SHARED:
        _SHARED[n] = ThreadedStepper(n)
    return _SHARED[n]
