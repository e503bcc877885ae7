"""How a game makes its moves: the setup, sense and act moves and the schedule of movers.

`Moves` is the half of `advgame.core.game.Game` that runs one move of the Disrupted-MDP (see
that module's docstring for the move protocol): `Game` builds the disruptor groups and the
PettingZoo surface, and inherits these steps. `advgame.core.lockstep` steps many games in
lockstep through the same methods (`_after_task`, `_begin_step`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from advgame.core.disruptor import Disruptor
from advgame.core.moves import ACT, SENSE, Move, protagonist_action
from advgame.core.schedule import Schedule
from advgame.core.task import StepResult, TaskBase

__all__ = ["Moves"]


class Moves:
    """The moves of a `Game` (a mixin: `Game.__init__` sets every attribute declared here)."""

    task: TaskBase
    protagonists: tuple[str, ...]
    disruptors: dict[str, Disruptor]
    agents: list[str]
    cost_weight: float
    move: str
    t: int
    next_movers: frozenset[str]
    last_reward: float
    episode_reward: float
    _sensing: list[Disruptor]
    _stale: list[Disruptor]
    _setup_ds: list[Disruptor]
    _action_ds: list[Disruptor]
    _reward_ds: list[Disruptor]
    _model_ds: list[Disruptor]
    _data_ds: list[Disruptor]
    _env_ds: list[Disruptor]
    _act_ds: list[Disruptor]
    _held_sensing: list[Disruptor]
    _p_spaces: dict[str, tuple[spaces.Space, tuple[int, ...] | None]]
    _constant: dict[str, bool]
    _dynamic: list[tuple[str, Schedule]]
    _fixed_movers: tuple[frozenset[str], frozenset[str]]
    _phase: str
    _rng: np.random.Generator
    _last: dict[str, np.ndarray]
    _active: dict[str, bool]
    _act_next: frozenset[str]
    _true_obs: dict[str, Any]
    _shown: dict[str, Any]
    _state: Any
    _setup_pending: bool
    _after_setup: tuple[str, frozenset[str]]

    def _plan_schedules(self) -> None:
        """Split the schedules into those constant in this phase and those drawn step by step.

        When all are constant, each step's movers are too: `_begin_step` then reuses them.
        """
        self._constant, self._dynamic = {}, []
        for a, d in self.disruptors.items():
            value = d.schedule.constant(self._phase)
            if value is None:
                self._dynamic.append((a, d.schedule))
            else:
                self._constant[a] = value
        if not self._dynamic:
            self._fixed_movers = self._movers(self._constant)

    def _setup(self, actions: Mapping[str, Any]) -> Move:
        """The setup move at t = 0: workspace adversaries edit the simulator, then it is re-observed."""
        clipped: dict[str, int] = {}
        sim = self.task.sim
        for d in self._setup_ds:
            if self._active[d.agent]:
                u, clipped[d.agent] = d.decode(actions[d.agent])
                self._last[d.agent] = u
                d.environment(sim, u)
        self._setup_pending = False
        obs = self.task.observe()
        self._true_obs, self._state, self._shown = obs, self.task.state(obs), dict(obs)
        self.move, self.next_movers = self._after_setup
        return Move(SENSE, clipped)

    # -- moves ------------------------------------------------------------------------------
    def _sense(self, actions: Mapping[str, Any]) -> Move:
        if self._setup_pending:
            return self._setup(actions)
        shown = self._shown  # the game's own dict (`_begin_step` built it; nobody else holds it)
        clipped: dict[str, int] = {}
        active = self._active
        for d in self._sensing:
            if active[d.agent]:
                u, clipped[d.agent] = d.decode(actions[d.agent])
                self._last[d.agent] = u
                d.observation(shown, u)
        self.move = ACT
        self.next_movers = self._act_next
        return Move(SENSE, clipped)

    def _act(self, actions: Mapping[str, Any]) -> Move:
        used: dict[str, np.ndarray] = {}
        clipped: dict[str, int] = {}
        active, last = self._active, self._last
        for d in self._act_ds:
            if active[d.agent]:
                u, clipped[d.agent] = d.decode(actions[d.agent])
                used[d.agent] = last[d.agent] = u
        acts: dict[str, Any] = {}
        for p, (space, shape) in self._p_spaces.items():
            acts[p] = protagonist_action(p, space, shape, actions[p])
        if self._env_ds:
            self._disrupt_environment(used)
        for d in self._action_ds:
            v = used.get(d.agent)  # `_effective`, inlined: this runs on every act move
            if v is None and d.schedule.hold:
                v = last.get(d.agent)
            if v is not None:
                d.action(acts, v, self._rng)
        return self._after_task(self.task.step(acts), used, clipped)

    def _after_task(
        self, result: StepResult, used: dict[str, np.ndarray], clipped: dict[str, int]
    ) -> Move:
        """The rest of an act move once the task has stepped (`result` of ``task.step``)."""
        obs, reward, cost, terminated, truncated, info = result
        payoff = reward - self.cost_weight * cost
        self.last_reward = reward
        self.episode_reward += reward
        rewards = dict.fromkeys(self.protagonists, reward)
        costs = dict.fromkeys(self.protagonists, cost)
        for d in self._reward_ds:
            v = self._effective(d, used)
            if v is not None:
                d.reward(rewards, costs, v)
        self.t += 1
        if terminated or truncated:
            self._true_obs = self._shown = obs
            self._state = self.task.state(obs)
            self.agents = []
            self.next_movers = frozenset()
        else:
            self._begin_step(obs, used)
        return Move(ACT, clipped, rewards, costs, reward, cost, payoff, terminated, truncated, info)

    def _disrupt_environment(self, used: dict[str, np.ndarray]) -> None:
        # `_env_ds` lists model edits (dynamics, which may recompile the model) before data
        # edits (forces), so forces land in the data of the model that will step.
        sim = self.task.sim
        epoch = sim.epoch
        for d in self._model_ds:
            d.environment(sim, used.get(d.agent))
        if sim.epoch != epoch:  # a recompile dropped edits made before it on the old model
            for d in self._model_ds:
                d.environment(sim, None)
        for d in self._data_ds:
            d.environment(sim, used.get(d.agent))

    def _begin_step(self, obs: dict[str, Any], pending: dict[str, np.ndarray] | None) -> None:
        """Record the true state of step t, draw its schedule, and build what agents see."""
        self._true_obs = obs
        self._state = self.task.state(obs)
        if self._dynamic:
            active = {**self._constant}
            t, phase, rng = self.t, self._phase, self._rng
            for a, schedule in self._dynamic:
                active[a] = schedule.is_active(t, phase, rng)
            sense_movers, self._act_next = self._movers(active)
        else:
            active = self._constant
            sense_movers, self._act_next = self._fixed_movers
        self._active = active
        shown = dict(obs)
        for d in self._stale:  # δ chosen in the act move that produced this observation
            u = (pending or {}).get(d.agent)
            if u is None and d.schedule.hold:
                u = self._last.get(d.agent)
            if u is not None:
                d.observation(shown, u)
        for d in self._held_sensing:
            if not active[d.agent] and d.agent in self._last:
                d.observation(shown, self._last[d.agent])
        self._shown = shown
        if sense_movers:
            self.move, self.next_movers = SENSE, sense_movers
        else:
            self.move, self.next_movers = ACT, self._act_next
        if self._setup_pending:  # t = 0: a setup move comes first, if a workspace adversary acts
            setup = frozenset(d.agent for d in self._setup_ds if active[d.agent])
            self._setup_pending = bool(setup)
            if setup:
                self._after_setup = (self.move, self.next_movers)
                self.move, self.next_movers = SENSE, setup

    def _movers(self, active: Mapping[str, bool]) -> tuple[frozenset[str], frozenset[str]]:
        """Who moves in a step with these active disruptors: (sense move, act move)."""
        sense = frozenset(d.agent for d in self._sensing if active[d.agent])
        act = frozenset([*self.protagonists, *(d.agent for d in self._act_ds if active[d.agent])])
        return sense, act

    def _effective(self, d: Disruptor, used: dict[str, np.ndarray]) -> np.ndarray | None:
        u = used.get(d.agent)
        if u is None and d.schedule.hold:
            u = self._last.get(d.agent)
        return u

    def _restore_environment(self) -> None:
        if not (self._env_ds or self._setup_ds):
            return
        sim = self.task.sim
        if not any(d.schedule.persist for d in self._env_ds):
            sim.restore_model()
        for d in self._setup_ds + self._env_ds:
            if not d.schedule.persist:
                d.restore(sim)
