"""Meta-strategy solvers against matrix games whose equilibria are known."""

from __future__ import annotations

import numpy as np
import pytest

from advgame.errors import ConfigError, UnknownNameError
from advgame.workflows.metasolver import SOLVERS, fictitious_play, game_value, nash, solve, uniform

RPS = np.array([[0.0, -1.0, 1.0], [1.0, 0.0, -1.0], [-1.0, 1.0, 0.0]])


def test_rock_paper_scissors_is_uniform_with_value_zero() -> None:
    row, col = nash(RPS)
    np.testing.assert_allclose(row, [1 / 3] * 3, atol=1e-8)
    np.testing.assert_allclose(col, [1 / 3] * 3, atol=1e-8)
    assert abs(game_value(RPS, row, col)) < 1e-8


def test_a_dominated_strategy_game_gives_the_pure_strategy() -> None:
    # row 1 dominates row 0; against row 1 the column player picks column 1 (2 < 4)
    m = np.array([[1.0, 0.0], [4.0, 2.0], [0.5, -1.0]])
    row, col = nash(m)
    np.testing.assert_allclose(row, [0, 1, 0], atol=1e-8)
    np.testing.assert_allclose(col, [0, 1], atol=1e-8)
    assert game_value(m, row, col) == pytest.approx(2.0, abs=1e-8)


def test_a_mixed_2x2_game_matches_its_closed_form() -> None:
    # [[a, b], [c, d]] without a saddle point: x = (d - c) / (a - b - c + d)
    a, b, c, d = 3.0, -1.0, -2.0, 1.0
    row, col = nash(np.array([[a, b], [c, d]]))
    den = a - b - c + d
    np.testing.assert_allclose(row, [(d - c) / den, (a - b) / den], atol=1e-8)
    np.testing.assert_allclose(col, [(d - b) / den, (a - c) / den], atol=1e-8)


@pytest.mark.parametrize("seed", range(5))
def test_random_matrices_have_max_min_equal_to_min_max(seed: int) -> None:
    m = np.random.default_rng(seed).normal(size=(4 + seed, 6 - seed % 3))
    row, col = nash(m)
    assert row.min() >= 0 and col.min() >= 0
    assert row.sum() == pytest.approx(1.0) and col.sum() == pytest.approx(1.0)
    max_min = float((row @ m).min())  # the row mixture guarantees at least this
    min_max = float((m @ col).max())  # the column mixture concedes at most this
    assert abs(max_min - min_max) < 1e-8
    assert game_value(m, row, col) == pytest.approx(max_min, abs=1e-8)


def test_fictitious_play_approaches_the_equilibrium() -> None:
    row, col = fictitious_play(RPS, iterations=3000)
    assert np.abs(row - 1 / 3).max() < 0.05 and np.abs(col - 1 / 3).max() < 0.05
    exploit = float((RPS @ col).max() - (row @ RPS).min())  # 0 at an equilibrium
    assert 0 <= exploit < 0.1


def test_uniform_and_the_registry() -> None:
    row, col = uniform(np.zeros((2, 5)))
    assert row.tolist() == [0.5, 0.5] and col.tolist() == [0.2] * 5
    assert set(SOLVERS) == {"uniform", "fictitious", "nash"}
    np.testing.assert_allclose(solve(RPS, "nash")[0], [1 / 3] * 3, atol=1e-8)
    with pytest.raises(UnknownNameError, match='Did you mean "nash"'):
        solve(RPS, "nahs")
    with pytest.raises(ConfigError, match="non-finite"):
        nash(np.array([[1.0, np.nan]]))
    with pytest.raises(ConfigError, match="2-D"):
        nash(np.zeros(3))
