"""The array form of a disruptor: its budget decode and its hook over ``[M, ...]`` rows.

`advgame.core.array_game.ArrayGame` holds N copies of a scenario and disrupts them as arrays:
one runtime per disruptor (the copies share its spec, so its budget) applies the hook to the
rows of every copy at once. `ArrayHooks` is the part of `advgame.core.disruptor.Disruptor`
that does it; its defaults apply the single-copy hook row by row (the same code, so the same
values), and the observation, action and reward runtimes override them with one ``[M, ...]``
sum, clip and cast: the observation and action ones call the very function their single-copy
hook calls on one row (`advgame.disruptors.observation.moved`, `ActionRuntime.moved`), so
every row is the single game's value bit for bit (``tests/test_array_game.py``).

What an array hook cannot batch it still does row by row: draws from each copy's own
generator (the probabilistic action mode, Discrete actions), Dict observations, L2
projections of adversary actions outside the ball (the check itself is one pass).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from advgame.errors import ActionError

__all__ = ["ArrayHooks"]


class ArrayHooks:
    """Array forms of a disruptor's decode and hooks (mixed into `Disruptor`)."""

    agent: str
    shape: tuple[int, ...]
    action_space: Any

    def _passes(self, u: np.ndarray) -> bool:  # pragma: no cover - `Disruptor` defines it
        raise NotImplementedError

    def _clip(self, u: np.ndarray) -> tuple[np.ndarray, int]:  # pragma: no cover - as above
        raise NotImplementedError

    def decode_array(self, actions: Any, rows: int) -> tuple[np.ndarray, np.ndarray]:
        """`decode` of each of `rows` actions ``[rows, size]``: the rows and their clip counts.

        One finiteness and box test covers the batch in the common case; otherwise each row
        is clipped (and L2-projected) as `decode` would, without touching ``clip_count``
        (copies keep their own counts).

        Raises:
            ActionError: not numeric, a wrong shape, or NaN/inf in a row (named).

        """
        try:
            u = np.asarray(actions, dtype=np.float64)
        except (TypeError, ValueError):
            raise ActionError(
                f"Actions for {self.agent!r} are not a numeric array of shape "
                f"({rows}, {self.shape[0]}); got {type(actions).__name__}."
            ) from None
        if u.shape != (rows, *self.shape):
            raise ActionError(
                f"Actions for {self.agent!r} have shape {u.shape}; expected {(rows, *self.shape)} "
                f"(one row per copy, each in {self.action_space})."
            )
        counts = np.zeros(rows, np.int64)
        if self._passes(u):
            return u, counts
        out = np.empty_like(u)
        for i in range(rows):
            try:
                out[i], counts[i] = self._clip(u[i])
            except ActionError as e:
                raise ActionError(f"Copy {i}: {e}") from None
        return out, counts

    def observation_array(self, observations: dict[str, np.ndarray], u: np.ndarray) -> None:
        """`observation` of every row: ``observations[target]`` is ``[M, ...]``, `u` ``[M, k]``."""
        rows = _rows(observations, len(u))
        for row, ui in zip(rows, u, strict=True):
            self.observation(row, ui)  # type: ignore[attr-defined]
        _restack(observations, rows)

    def action_array(
        self, actions: dict[str, np.ndarray], u: np.ndarray, rngs: Sequence[np.random.Generator]
    ) -> None:
        """`action` of every row, row ``i`` drawing from ``rngs[i]`` (its copy's generator)."""
        rows = _rows(actions, len(u))
        for row, ui, rng in zip(rows, u, rngs, strict=True):
            self.action(row, ui, rng)  # type: ignore[attr-defined]
        _restack(actions, rows)

    def reward_array(
        self, rewards: dict[str, np.ndarray], costs: dict[str, np.ndarray], u: np.ndarray
    ) -> None:
        """`reward` of every row: ``rewards[target]`` and ``costs[target]`` are ``[M]``."""
        for i, ui in enumerate(u):
            r = {t: float(v[i]) for t, v in rewards.items()}
            c = {t: float(v[i]) for t, v in costs.items()}
            self.reward(r, c, ui)  # type: ignore[attr-defined]
            for t, v in r.items():
                rewards[t][i] = v
            for t, v in c.items():
                costs[t][i] = v


def _rows(arrays: Mapping[str, np.ndarray], n: int) -> list[dict[str, Any]]:
    return [{k: v[i] for k, v in arrays.items()} for i in range(n)]


def _restack(arrays: dict[str, np.ndarray], rows: list[dict[str, Any]]) -> None:
    for k in arrays:
        arrays[k] = np.stack([row[k] for row in rows])
