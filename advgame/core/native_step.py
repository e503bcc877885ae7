"""One call per thread instead of one per env: a batch's ``mj_step`` loop compiled without the GIL.

`advgame.core.physics.ThreadedStepper` steps N MuJoCo simulations. Through MuJoCo's Python
bindings that is a Python loop with one binding call per env, and each call releases the GIL and
takes it back, so two threads stepping halves of a batch keep handing the GIL to each other.
`native_loop` gives the same loop as one function, compiled by numba with ``nogil=True``, that
calls MuJoCo's own C functions (``mju_copy`` for the controls, ``mj_step`` ``nstep`` times,
``mj_rnePostConstraint``) from the library the bindings loaded, on the envs' own ``mjModel`` and
``mjData`` (their ``_address``). The C calls are the bindings' calls in the same order on the
same memory, so every env evolves bit for bit as through the bindings
(``tests/test_native_step.py`` runs both loops side by side).

Measured on the 2-core VM (7 Dec 2026, training stopped, per-round ratios, median of 10-15
rounds): the physics alone (`benchmarks/bench_batch_physics.py`, ``stepper-tK / bindings-tK``)
1.03 / 1.02 at 8 HalfCheetah-v5 envs on one / two threads, 1.04 / 1.05 at 64; the array game
with its adversaries (`benchmarks/bench_array_game.py --bindings`, the fields read in the loop
too) 1.00 / 1.00 at 8 copies, 1.04 / 1.13 at 64. The gain is where two threads hand the GIL to
each other once per env.

When it is not used: numba is not importable (it is not a core dependency; the ``robosuite``
extra, and so ``.[all]``, installs it), the library cannot be found next to the bindings, or the
environment variable `NATIVE_VAR` is ``0``. The bindings' loop runs then, with the same results.
One difference remains: a fatal MuJoCo error inside the compiled loop (``mju_error``: a stack
overflow in ``mj_stackAlloc``, say; arena overflows are warnings) ends the process with MuJoCo's
message, where the bindings raise ``mujoco.FatalError``. Set ``ADVGAME_NATIVE_STEP=0`` to debug
such a model.

The loop also copies the ``MjData`` fields a batched task reads (``qpos``, ``qvel``,
``cfrc_ext``) into ``[N, ...]`` rows, each just before or just after its env's substeps
(``mju_copy`` of the same doubles: what ``np.array`` of the fields gives), so that reading them
costs no Python per env either; `BatchPointers` keeps the addresses.
"""

from __future__ import annotations

import functools
import operator
import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from advgame.core.mujoco_timers import mujoco_library

__all__ = ["NATIVE_VAR", "BatchPointers", "Layout", "PointerCache", "native_loop"]

NATIVE_VAR = "ADVGAME_NATIVE_STEP"
"""Environment variable: ``0`` keeps the bindings' Python loop (the compiled loop is the default)."""


@functools.cache
def native_loop() -> Callable[..., None] | None:
    """The compiled loop, built once per process; ``None`` where it cannot be (module docstring).

    The loop is ``loop(models, datas, ctrls, src, nu, nstep, post, lo, hi, pre, post_fields)``:
    for ``k`` in ``range(lo, hi)`` it copies each field of `pre` (below) into row ``k`` of its
    output, row ``k`` of the C-contiguous float64 ``[N, nu]`` array `src` into the ``nu``
    doubles at ``ctrls[k]``, steps ``(models[k], datas[k])`` `nstep` times, calls
    ``mj_rnePostConstraint`` if `post`, and copies the fields of `post_fields`. ``models``,
    ``datas`` and ``ctrls`` are uint64 arrays of addresses (``MjModel._address``,
    ``MjData._address``, ``data.ctrl.ctypes.data``); a field list is ``(sources, block, offsets,
    sizes)``, as `Layout.arguments` gives it: uint64 ``[F, N]`` addresses of each env's
    field, the float64 block the rows go to, and int64 ``[F]`` offsets and sizes (doubles per
    env) of the fields in it.
    """
    if os.environ.get(NATIVE_VAR, "").strip() == "0":
        return None
    try:
        import numba
    except ImportError:
        return None
    library = mujoco_library()
    if library is None:
        return None
    return _compile(numba, library)


def _compile(numba: Any, library: Any) -> Callable[..., None]:
    import ctypes

    u64 = ctypes.c_uint64  # pointers, passed in the integer registers as uint64 values are
    mj_step, post_constraint, copy = (
        library.mj_step,
        library.mj_rnePostConstraint,
        library.mju_copy,
    )
    for fn, args in ((mj_step, [u64, u64]), (post_constraint, [u64, u64])):
        fn.argtypes, fn.restype = args, None
    copy.argtypes, copy.restype = [u64, u64, ctypes.c_int], None

    @numba.njit(nogil=True, cache=False)
    def fields(k, sources, block, offsets, sizes):
        # field f of env k goes to row k of the field's [N, size] part of the block
        n = sources.shape[1]
        for f in range(sources.shape[0]):
            copy(block.ctypes.data + (offsets[f] * n + k * sizes[f]) * 8, sources[f, k], sizes[f])

    @numba.njit(nogil=True, cache=False)
    def loop(models, datas, ctrls, src, nu, nstep, post, lo, hi, pre, post_fields):
        base = src.ctypes.data
        row = nu * 8  # float64 bytes per row
        for k in range(lo, hi):
            fields(k, pre[0], pre[1], pre[2], pre[3])
            copy(ctrls[k], base + k * row, nu)
            for _ in range(nstep):
                mj_step(models[k], datas[k])
            if post:
                post_constraint(models[k], datas[k])
            fields(k, post_fields[0], post_fields[1], post_fields[2], post_fields[3])

    return loop


class BatchPointers:
    """The addresses of one batch's simulations, for the compiled loop.

    Args:
        pairs: each env's ``(model, data)``, in row order (held here: while this object lives,
            none of those addresses can be freed and reused).

    Attributes:
        models: uint64 ``[N]``, each ``MjModel._address``.
        datas: uint64 ``[N]``, each ``MjData._address``.
        ctrls: uint64 ``[N]``, each ``data.ctrl`` buffer's address.
        nu: the envs' common control size (-1 where they differ: the loop is not used).

    """

    def __init__(self, pairs: list[tuple[Any, Any]]) -> None:
        self.pairs = pairs
        self.models = np.array([m._address for m, _ in pairs], np.uint64)
        self.datas = np.array([d._address for _, d in pairs], np.uint64)
        self.ctrls = np.array([d.ctrl.ctypes.data for _, d in pairs], np.uint64)
        self._options = [m.opt for m, _ in pairs]  # views of each model's own options
        sizes = {len(d.ctrl) for _, d in pairs}
        self.nu = sizes.pop() if len(sizes) == 1 else -1
        self._layouts: dict[tuple[str, ...], Layout | None] = {}

    def timesteps(self) -> np.ndarray:
        """float64 ``[N]``: each model's ``opt.timestep`` now (an edited timestep shows).

        Read through options objects made once per batch: ``model.opt`` makes a new one on
        every read, which cost more than the read itself.
        """
        return np.fromiter(map(_TIMESTEP, self._options), np.float64, len(self._options))

    def layout(self, names: tuple[str, ...]) -> Layout | None:
        """Where the loop reads `names` from in every env (made once per tuple of names).

        ``None`` when a field is not a C-contiguous float64 array of one shape in every env
        (the loop copies doubles only): the bindings' loop then reads the batch.
        """
        if names not in self._layouts:
            self._layouts[names] = Layout.of(names, [d for _, d in self.pairs])
        return self._layouts[names]


class Layout:
    """Some ``MjData`` fields of N envs and where their ``[N, ...]`` rows go in one block.

    Args:
        sources: uint64 ``[F, N]``: the address of field ``f`` in env ``k``.
        shapes: each field's shape in one env.

    """

    def __init__(self, sources: np.ndarray, shapes: list[tuple[int, ...]]) -> None:
        self.sources, self.shapes = sources, shapes
        self.sizes = np.array([int(np.prod(s)) for s in shapes], np.int64)
        self.offsets = np.cumsum(self.sizes) - self.sizes  # where each field starts
        self.total = int(self.sizes.sum())

    @classmethod
    def of(cls, names: tuple[str, ...], datas: list[Any]) -> Layout | None:
        """The layout of `names` in `datas`, or ``None`` where the loop cannot copy one."""
        sources, shapes = [], []
        for name in names:
            arrays = [getattr(d, name) for d in datas]
            found = {a.shape for a in arrays}
            if len(found) != 1 or not all(
                a.dtype == np.float64 and a.flags.c_contiguous for a in arrays
            ):
                return None
            sources.append([a.ctypes.data for a in arrays])
            shapes.append(found.pop())
        return cls(np.array(sources, np.uint64).reshape(len(names), len(datas)), shapes)

    def arguments(self) -> tuple[tuple[np.ndarray, ...], list[np.ndarray]]:
        """A new block for one step: the loop's argument and each field's ``[N, ...]`` view."""
        n = self.sources.shape[1]
        block = np.empty(self.total * n)
        views = [
            block[o * n : (o + z) * n].reshape(n, *shape)
            for o, z, shape in zip(
                self.offsets.tolist(), self.sizes.tolist(), self.shapes, strict=True
            )
        ]
        return (self.sources, block, self.offsets, self.sizes), views


class PointerCache:
    """`BatchPointers` of the last few batches a stepper stepped, found by their objects.

    A batch is the same when its envs have the same ``model`` and ``data`` objects in the same
    order (compared by identity first, in C); a model a dynamics disruptor swapped in, or a new
    data, makes a new entry.
    """

    KEPT = 4
    """Batches kept (training views and evaluations step several batches in turn).

    A dynamics disruptor that changes a body's length recompiles its copy's model and data on
    every step it acts, so each such step makes an entry, and the kept entries hold the
    replaced models and datas until they leave (at most this many batches of them).
    """

    def __init__(self) -> None:
        self._kept: list[BatchPointers] = []  # newest first

    def get(self, owners: Sequence[Any]) -> BatchPointers:
        """The pointers of `owners` (objects with ``model`` and ``data``), made once."""
        pairs = list(map(_MODEL_DATA, owners))
        for i, kept in enumerate(self._kept):
            if kept.pairs == pairs:
                if i:
                    self._kept.insert(0, self._kept.pop(i))
                return kept
        made = BatchPointers(pairs)
        self._kept.insert(0, made)
        del self._kept[self.KEPT :]
        return made


_MODEL_DATA = operator.attrgetter("model", "data")
_TIMESTEP = operator.attrgetter("timestep")
