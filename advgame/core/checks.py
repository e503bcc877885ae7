"""Cheap numeric tests of one action, on the path of every move.

A game checks every action it is sent (`advgame.core.moves.protagonist_action`,
`advgame.core.disruptor.Disruptor.decode`) on every move, and these checks cost about as much as
the perturbations themselves: for the few entries of one action, Python's builtins over
``a.tolist()`` beat a numpy reduction (whose keyword handling alone takes longer), and numpy's
clip ufunc beats ``ndarray.clip``'s Python wrapper. Each function is exact: its answer is the
one the plain numpy expression gives (``tests/test_checks.py``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["SMALL", "all_finite", "all_set", "any_set", "clip_ufunc", "in_unit_box"]

# `clip_ufunc`: the ufunc behind `np.clip` and `ndarray.clip` (same loops, same results) without
# their Python wrapper, which costs more than the clip of one action.
try:  # numpy >= 1.26 (numpy 2 warns on `numpy.core`)
    from numpy._core.multiarray import count_nonzero as _count  # type: ignore[import-not-found,attr-defined,unused-ignore]
    from numpy._core.umath import clip as clip_ufunc  # type: ignore[import-not-found,attr-defined,unused-ignore]
except ImportError:  # pragma: no cover - older numpy
    from numpy.core.multiarray import count_nonzero as _count  # type: ignore[attr-defined,no-redef,unused-ignore]
    from numpy.core.umath import clip as clip_ufunc  # type: ignore[attr-defined,no-redef,unused-ignore]

SMALL = 64
"""Up to this many entries, Python's ``sum(a.tolist())`` beats a numpy reduction."""


def all_finite(a: np.ndarray) -> bool:
    """Whether every entry of the real array `a` is finite; one cheap pass when it is.

    NaN or inf makes the sum (of the entries, or of their squares) non-finite; so can an
    overflow of finite values, which the exact test then settles.
    """
    flat = a if a.ndim == 1 else a.reshape(-1)
    total = sum(flat.tolist()) if flat.size <= SMALL else flat.dot(flat)
    return math.isfinite(total) or bool(np.isfinite(a).all())


def in_unit_box(u: np.ndarray) -> bool:
    """Whether every entry of the float array `u` (any shape) lies in ``[-1, 1]`` (NaN does not).

    Up to `SMALL` entries (one action, or a few copies' rows of one) are tested in Python: a
    numpy reduction costs about as much as the simulator's own Python per step. `min` and
    `max` skip a NaN that is not first, so the sum (NaN if any entry is) settles it.
    """
    if 0 < u.size <= SMALL:
        flat = (u if u.ndim == 1 else u.reshape(-1)).tolist()
        return min(flat) >= -1.0 and max(flat) <= 1.0 and math.isfinite(sum(flat))
    return bool(np.maximum.reduce(np.abs(u), axis=None, initial=0.0) <= 1.0)  # NaN: False


def any_set(mask: np.ndarray) -> bool:
    """``mask.any()`` of a bool (or integer) array: numpy's C count of its nonzero entries.

    The array game tests its row masks several times a step; ``ndarray.any`` goes through a
    Python wrapper and a reduction (0.9 µs on 8 entries here), the count 0.04 µs.
    """
    return bool(_count(mask))  # an int, or numpy's int64 on numpy 2


def all_set(mask: np.ndarray) -> bool:
    """``mask.all()`` of a bool array (True for an empty one), as `any_set` counts."""
    return bool(_count(mask) == mask.size)
