"""Meta-strategy solvers of a zero-sum meta-game: uniform, fictitious play, Nash by LP.

The meta-game of a population is the empirical payoff matrix ``M[i, j]``: the protagonist
``i``'s mean true return against adversary ``j``. The protagonist maximizes, the adversary
minimizes. A solver maps ``M`` to a pair of mixed strategies ``(row, column)``; as in
OpenSpiel's PSRO, the solvers are a plain dict of functions, `SOLVERS`::

    row, col = SOLVERS["nash"](np.array([[0, -1, 1], [1, 0, -1], [-1, 1, 0]]))

`nash` solves the row player's linear program ``max v s.t. Mᵀx >= v, Σx = 1, x >= 0``
(and the column player's dual one) with `scipy.optimize.linprog`; `game_value` is ``xᵀMy``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from advgame.errors import ConfigError, UnknownNameError, did_you_mean

__all__ = ["SOLVERS", "fictitious_play", "game_value", "nash", "solve", "uniform"]

Strategies = tuple[np.ndarray, np.ndarray]


def _matrix(payoffs: np.ndarray) -> np.ndarray:
    m = np.asarray(payoffs, dtype=np.float64)
    if m.ndim != 2 or 0 in m.shape:
        raise ConfigError(f"A meta-game needs a non-empty 2-D payoff matrix, got shape {m.shape}.")
    if not np.all(np.isfinite(m)):
        raise ConfigError(
            f"The meta-game matrix has non-finite entries at {np.argwhere(~np.isfinite(m)).tolist()}"
            "; evaluate every (protagonist, adversary) pair before solving."
        )
    return m


def uniform(payoffs: np.ndarray) -> Strategies:
    """Return the uniform mixtures over rows and columns (PSRO with uniform = fictitious self-play)."""
    m = _matrix(payoffs)
    return np.full(m.shape[0], 1 / m.shape[0]), np.full(m.shape[1], 1 / m.shape[1])


def fictitious_play(payoffs: np.ndarray, iterations: int = 2000) -> Strategies:
    """Return the empirical mixtures of `iterations` rounds of simultaneous fictitious play.

    Each round both players best-respond to the other's empirical mixture so far (ties: the
    lowest index), starting from row 0 and column 0. The mixtures converge to a Nash
    equilibrium of a zero-sum game (Robinson, 1951), slowly: ``O(iterations^(-1/2))``-ish.

    Example (the equilibrium is row (1/2, 1/2), column (1/4, 3/4)):
        >>> row, col = fictitious_play(np.array([[3.0, 1.0], [0.0, 2.0]]), iterations=1000)
        >>> row.round(2).tolist(), col.round(2).tolist()
        ([0.5, 0.5], [0.24, 0.76])

    """
    m = _matrix(payoffs)
    if type(iterations) is not int or iterations < 1:
        raise ConfigError(f"iterations must be an int >= 1, got {iterations!r}.")
    rows, cols = np.zeros(m.shape[0]), np.zeros(m.shape[1])
    rows[0] = cols[0] = 1.0
    for t in range(1, iterations):
        r = int(np.argmax(m @ (cols / t)))
        c = int(np.argmin((rows / t) @ m))
        rows[r] += 1.0
        cols[c] += 1.0
    return rows / iterations, cols / iterations


def _maximin(m: np.ndarray) -> tuple[np.ndarray, float]:
    """The row player's maximin mixture of `m` and its value, by linear programming."""
    from scipy.optimize import linprog

    n_rows, n_cols = m.shape
    # variables (x_1..x_n, v): minimize -v  s.t.  v - (Mᵀx)_j <= 0,  Σx = 1,  x >= 0
    c = np.zeros(n_rows + 1)
    c[-1] = -1.0
    a_ub = np.hstack([-m.T, np.ones((n_cols, 1))])
    a_eq = np.concatenate([np.ones(n_rows), [0.0]])[None, :]
    bounds = [(0.0, None)] * n_rows + [(None, None)]
    res = linprog(c, A_ub=a_ub, b_ub=np.zeros(n_cols), A_eq=a_eq, b_eq=[1.0], bounds=bounds,
                  method="highs")  # fmt: skip
    if not res.success:  # cannot happen for a finite matrix; say so if it does
        raise ConfigError(f"The meta-game LP failed ({res.message}) on the matrix {m.tolist()}.")
    x = np.clip(res.x[:-1], 0.0, None)
    return x / x.sum(), float(res.x[-1])


def nash(payoffs: np.ndarray) -> Strategies:
    """Return a Nash equilibrium of the zero-sum game `payoffs` (row maximizes, column minimizes).

    Two linear programs: the row player's maximin and the column player's minimax (the row
    player's maximin of ``-Mᵀ``); by the minimax theorem both reach the value of the game.

    Example:
        >>> row, col = nash(np.array([[0.0, -1.0, 1.0], [1.0, 0.0, -1.0], [-1.0, 1.0, 0.0]]))
        >>> row.round(6).tolist(), col.round(6).tolist()
        ([0.333333, 0.333333, 0.333333], [0.333333, 0.333333, 0.333333])

    """
    m = _matrix(payoffs)
    row, _ = _maximin(m)
    col, _ = _maximin(-m.T)
    return row, col


def game_value(payoffs: np.ndarray, row: np.ndarray, col: np.ndarray) -> float:
    """Return the row player's expected payoff ``rowᵀ M col`` of the mixtures."""
    return float(np.asarray(row) @ _matrix(payoffs) @ np.asarray(col))


SOLVERS: dict[str, Callable[[np.ndarray], Strategies]] = {
    "uniform": uniform,
    "fictitious": fictitious_play,
    "nash": nash,
}
"""Meta-strategy solvers by name: matrix -> (row mixture, column mixture)."""


def solve(payoffs: np.ndarray, solver: str) -> Strategies:
    """Return ``SOLVERS[solver](payoffs)``; an unknown name is an error with a suggestion."""
    if solver not in SOLVERS:
        hint = did_you_mean(solver, SOLVERS)
        raise UnknownNameError(
            f"Unknown meta-solver {solver!r}.{hint} Expected one of {list(SOLVERS)}."
        )
    return SOLVERS[solver](payoffs)
