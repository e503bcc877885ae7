"""Shared by the multi-agent protagonist tests (tests/test_marl_*.py): the MaMuJoCo scenario,
Gaussian noise for every adversary of a game, and an exact recursive equality."""

from __future__ import annotations

from typing import Any

import numpy as np

import advgame
from advgame.adversaries import GaussianAdversary

SID = "MA-HalfCheetah-2x3"


def noisy(game: advgame.Game, std: float = 0.05) -> dict[str, Any]:
    return {a: GaussianAdversary(std=std) for a in game.adversaries}


def _assert_same(a: Any, b: Any, where: str = "") -> None:
    """Exact, recursive equality (dicts, sequences, arrays with dtype, scalars with type)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), f"{where}: {a.keys()} != {b}"
        for k in a:
            _assert_same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), f"{where}: {a!r} != {b!r}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert np.asarray(a).dtype == np.asarray(b).dtype, f"{where}: dtypes differ"
        assert np.array_equal(a, b), f"{where}: {a} != {b}"
    else:
        assert type(a) is type(b) and a == b, f"{where}: {a!r} != {b!r}"
