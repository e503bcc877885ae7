"""How an `ArrayGame` makes its moves: the sense and act calls over ``[N, ...]`` arrays.

`ArrayMoves` is the half of `advgame.core.array_game.ArrayGame` that plays one move of the
Disrupted-MDP for every copy at once (the protocol is `advgame.core.game`'s): the sense call
(observation adversaries' δ on the copies where they act), the act call (environment, action,
reward and cost adversaries around one batched step of the simulators, `TaskBase.step_arrays`),
and the start of the next step (schedules drawn as boolean arrays ``[N]``, held and stale
perturbations applied). `ArrayGame` builds the array state and keeps it in step with the copies'
`Game` objects (resets, `pull`, `push`), and inherits these moves, as `Game` inherits
`advgame.core.moving.Moves`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from gymnasium import spaces

from advgame.core.checks import all_set, any_set
from advgame.core.disruptor import Disruptor
from advgame.core.moves import protagonist_rows
from advgame.core.task import TaskBase
from advgame.errors import ActionError

if TYPE_CHECKING:
    from advgame.core.game import Game

__all__ = ["ArrayMoves", "ArrayStep"]


@dataclass
class ArrayStep:
    """What one act call of an `ArrayGame` returns, row ``i`` for copy ``i``."""

    rewards: dict[str, np.ndarray]
    """The reward each protagonist observes ``[N]`` (after reward disruptors)."""
    costs: dict[str, np.ndarray]
    """The cost each protagonist observes ``[N]`` (after cost disruptors)."""
    reward: np.ndarray
    """The true team reward ``[N]``."""
    cost: np.ndarray
    """The true team cost ``[N]``."""
    payoff: np.ndarray
    """``reward - cost_weight * cost``; every adversary is paid its negative."""
    terminated: np.ndarray
    """``[N]`` bool."""
    truncated: np.ndarray
    """``[N]`` bool (the time limit included)."""
    info: dict[str, np.ndarray]
    """The task's info terms ``[N, ...]``."""
    clipped: dict[str, np.ndarray]
    """Adversaries of the act move -> components clipped ``[N]`` (0 where it did not act)."""
    acted: dict[str, np.ndarray]
    """Adversaries of the act move -> whether its action counted ``[N]``."""
    observations: dict[str, np.ndarray]
    """The true observations after the step ``[N, ...]`` (final ones where an episode ended)."""


class ArrayMoves:
    """The moves of an `ArrayGame` (a mixin: `ArrayGame.__init__` sets every attribute here)."""

    games: list[Game]
    n: int
    phase: str
    threads: int | None
    protagonists: tuple[str, ...]
    disruptors: dict[str, Disruptor]
    cost_weight: float
    t: np.ndarray
    done: np.ndarray
    clip_count: dict[str, np.ndarray]
    last_clipped: dict[str, np.ndarray]
    _tasks: list[TaskBase]
    _task_type: type[TaskBase]
    _limit: int | None
    _sensing: list[Disruptor]
    _stale: list[Disruptor]
    _action_ds: list[Disruptor]
    _reward_ds: list[Disruptor]
    _env_ds: list[Disruptor]
    _act_ds: list[Disruptor]
    _p_spaces: dict[str, tuple[spaces.Space, tuple[int, ...] | None]]
    _rngs: list[np.random.Generator]
    _last: dict[str, np.ndarray]
    _has_last: dict[str, np.ndarray]
    _active: dict[str, np.ndarray]
    _true: dict[str, np.ndarray]
    _shown: dict[str, np.ndarray]

    def shown(self) -> dict[str, np.ndarray]:
        """What the protagonists are shown now (copies of the arrays)."""
        return {p: v.copy() for p, v in self._shown.items()}

    def sense(self, actions: Mapping[str, Any], rows: Any = None) -> dict[str, np.ndarray]:
        """The sense move: each active observation adversary's δ added to what copies show.

        ``actions[agent]`` holds one row per copy for every sensing adversary (rows of copies
        where it does not act are ignored); `rows` (a bool mask) limits the move to some
        copies. Returns the protagonists' shown observations; `last_clipped` the clips.
        """
        mask = None if rows is None else np.asarray(rows, np.bool_)
        self._require(mask)
        for d in self._sensing:
            on = self._active[d.agent] if mask is None else self._active[d.agent] & mask
            if any_set(on):
                self.last_clipped[d.agent] = self._decode(d, actions, on)
                self._apply_obs(d, self._shown, self._last[d.agent], on)
            else:
                self.last_clipped[d.agent] = np.zeros(self.n, np.int64)
        return self.shown()

    def act(self, actions: Mapping[str, Any]) -> ArrayStep:
        """The act move of every copy; the simulators step as one batch.

        ``actions`` holds ``[N, ...]`` for every protagonist and every act-move adversary
        (environment, action, reward, stale observation). Finished copies stay `done` until `reset`.
        """
        self._require()
        clipped: dict[str, np.ndarray] = {}
        acted: dict[str, np.ndarray] = {}
        for d in self._act_ds:
            rows = acted[d.agent] = self._active[d.agent].copy()
            clipped[d.agent] = self._decode(d, actions, rows) if any_set(rows) else rows * 0
        acts = {}
        for p, (space, shape) in self._p_spaces.items():
            checked = protagonist_rows(p, space, shape, self._take(actions, p))
            acts[p] = checked if isinstance(checked, np.ndarray) else np.stack(checked)
        if self._env_ds:
            self._disrupt_environment(acted)
        for d in self._action_ds:
            rows = self._effective(d)
            if all_set(rows):
                d.action_array(acts, self._last[d.agent], self._rngs)
            elif any_set(rows):
                sub = {p: v[rows] for p, v in acts.items()}
                d.action_array(sub, self._last[d.agent][rows], self._rows(rows))
                for p in acts:  # a copy: `acts[p]` may be the caller's own array
                    acts[p] = acts[p].copy()
                    acts[p][rows] = sub[p]
        return self._after_task(acts, clipped, acted)

    def _after_task(self, acts: dict[str, np.ndarray], clipped: dict, acted: dict) -> ArrayStep:
        r = self._task_type.step_arrays(self._tasks, acts, self.threads)
        payoff = r.reward - self.cost_weight * r.cost
        rewards = {p: r.reward.copy() for p in self.protagonists}
        costs = {p: r.cost.copy() for p in self.protagonists}
        for d in self._reward_ds:
            rows = self._effective(d)
            if all_set(rows):
                d.reward_array(rewards, costs, self._last[d.agent])
            elif any_set(rows):
                sub_r = {p: v[rows] for p, v in rewards.items()}
                sub_c = {p: v[rows] for p, v in costs.items()}
                d.reward_array(sub_r, sub_c, self._last[d.agent][rows])
                for p in self.protagonists:
                    rewards[p][rows], costs[p][rows] = sub_r[p], sub_c[p]
        self.t += 1
        if self._limit is None:
            truncated = r.truncated.copy()
        else:
            truncated = r.truncated | (self.t >= self._limit)
        self.done = r.terminated | truncated
        self._true = dict(r.observations)
        self._begin_step(acted)
        return ArrayStep(
            rewards, costs, r.reward, r.cost, payoff, r.terminated.copy(), truncated,
            r.info, clipped, acted, {p: v.copy() for p, v in self._true.items()},
        )  # fmt: skip

    def _begin_step(self, pending: Mapping[str, np.ndarray]) -> None:
        """Draw step t's schedules of the live copies and build what their protagonists see."""
        live = ~self.done
        phase = self.phase
        for d in self.disruptors.values():
            value = d.schedule.constant(phase)
            if value is None:
                self._active[d.agent] = d.schedule.active_rows(self.t, phase, self._rngs, live)
            else:  # constant in this phase (the phase may have changed since the last step)
                self._active[d.agent][live] = value
        shown = {p: v.copy() for p, v in self._true.items()}
        for d in self._stale:  # δ chosen in the act move that produced this observation
            rows = pending[d.agent] if not d.schedule.hold else self._has_last[d.agent]
            self._apply_obs(d, shown, self._last[d.agent], rows & live)
        for d in self._sensing:
            if d.schedule.hold:
                rows = ~self._active[d.agent] & self._has_last[d.agent] & live
                self._apply_obs(d, shown, self._last[d.agent], rows)
        self._shown = shown

    # -- helpers --------------------------------------------------------------------------------
    def _require(self, mask: np.ndarray | None = None) -> None:
        done = self.done if mask is None else self.done & mask
        if any_set(done):
            rows = np.flatnonzero(done).tolist()
            raise ActionError(
                f"Copies {rows} have no live episode; call reset(rows=game.done) before moving."
            )

    def _take(self, actions: Mapping[str, Any], agent: str) -> Any:
        if agent not in actions:
            raise ActionError(
                f"This move needs actions for {agent!r}: one row per copy ({self.n} rows)."
            )
        return actions[agent]

    def _decode(self, d: Any, actions: Mapping[str, Any], rows: np.ndarray) -> np.ndarray:
        """Decode `d`'s actions on `rows` into its last perturbation; the clip counts ``[N]``."""
        a, every = self._take(actions, d.agent), all_set(rows)
        if not every:
            a = np.asarray(a)
            a = a[rows] if a.ndim and len(a) == self.n else a
        u, counts = d.decode_array(a, self.n if every else int(rows.sum()))
        last = self._last[d.agent]
        if every:
            last[...] = u
            out = counts
        else:
            last[rows] = u
            out = np.zeros(self.n, np.int64)
            out[rows] = counts
        self._has_last[d.agent] |= rows
        if any_set(out):  # nothing clipped (the common case): the counts stay as they are
            self.clip_count[d.agent] += out
        return out

    def _apply_obs(
        self, d: Any, shown: dict[str, np.ndarray], u: np.ndarray, rows: np.ndarray
    ) -> None:
        if all_set(rows):
            d.observation_array(shown, u)
        elif any_set(rows):
            sub = {p: v[rows] for p, v in shown.items()}
            d.observation_array(sub, u[rows])
            for p, v in sub.items():
                shown[p][rows] = v

    def _effective(self, d: Any) -> np.ndarray:
        """Copies where `d`'s perturbation is in force: it acted, or it holds its last one."""
        return self._has_last[d.agent] if d.schedule.hold else self._active[d.agent]

    def _rows(self, rows: np.ndarray) -> list[np.random.Generator]:
        return [self._rngs[i] for i in np.flatnonzero(rows)]

    def _disrupt_environment(self, acted: Mapping[str, np.ndarray]) -> None:
        """Each copy's environment disruptors edit its own model and data (as `Game` does)."""
        agents = [d.agent for d in self._env_ds]
        for i, g in enumerate(self.games):
            g._disrupt_environment({a: self._last[a][i] for a in agents if acted[a][i]})
