"""`advgame.core.checks`: each cheap test answers as the plain numpy expression does."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from advgame.core.checks import SMALL, all_finite, all_set, any_set, clip_ufunc, in_unit_box

EDGES = [-np.inf, -1.0000000000000002, -1.0, -0.0, 0.0, 1.0, 1.0000000000000002, np.inf, np.nan]
VALUES = st.one_of(st.sampled_from(EDGES), st.floats(-2, 2), st.floats(allow_nan=True))


def _box(u: np.ndarray) -> bool:
    return bool(np.all(np.abs(u) <= 1.0))  # NaN: False


@given(arrays(np.float64, st.integers(1, SMALL + 3), elements=VALUES))
def test_in_unit_box_is_the_numpy_test(u: np.ndarray) -> None:
    assert in_unit_box(u) == _box(u)
    assert in_unit_box(u.reshape(1, -1)) == _box(u)  # rows of a batch: in Python up to SMALL
    assert in_unit_box(np.stack([u, u]).T) == _box(u)  # a strided batch
    big = np.tile(u, (SMALL // u.size + 2, 1))  # more than SMALL entries: the numpy reduction
    assert big.size > SMALL and in_unit_box(big) == _box(u)


@given(arrays(np.float64, st.integers(1, SMALL + 3), elements=VALUES))
def test_all_finite_is_the_numpy_test(a: np.ndarray) -> None:
    assert all_finite(a) == bool(np.isfinite(a).all())


def test_in_unit_box_nan_anywhere() -> None:
    for i in range(6):
        u = np.zeros(6)
        u[i] = np.nan
        assert not in_unit_box(u)


@given(
    arrays(np.float64, 6, elements=VALUES), st.sampled_from([(-1.0, 1.0), (0.0, 1.0), (-1.0, 0.0)])
)
def test_clip_ufunc_is_ndarray_clip(a: np.ndarray, bounds: tuple[float, float]) -> None:
    lo, hi = np.full(6, bounds[0]), np.full(6, bounds[1])
    got, want = clip_ufunc(a, lo, hi), a.clip(lo, hi)
    assert got.tobytes() == want.tobytes()  # bit for bit, signed zeros and NaN included


@pytest.mark.parametrize("size", [0, 1, 3, 8, 64, 1000])
def test_any_set_and_all_set_are_numpys_any_and_all_of_a_bool_mask(size: int) -> None:
    rng = np.random.default_rng(size)
    for mask in (
        np.zeros(size, np.bool_),
        np.ones(size, np.bool_),
        rng.random(size) < 0.5,
        np.ones((size, 2), np.bool_)[:, 0],  # a strided view
    ):
        assert any_set(mask) == bool(mask.any())
        assert all_set(mask) == bool(mask.all())
        assert isinstance(any_set(mask), bool) and isinstance(all_set(mask), bool)
