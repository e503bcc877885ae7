"""The game: a Disrupted-MDP as a PettingZoo `ParallelEnv`.

Agents are the task's protagonists plus one adversary per disruptor. One protagonist step
``t`` of the Disrupted-MDP is one or two *moves* (calls to `Game.step`):

1. **sense move** (only when an observation disruptor with ``timing="sense"`` acts at ``t``):
   the observation adversaries, which observe the true state ``s_t``, choose ``δ_t``; the
   protagonists receive ``s_t + δ_t``. Nobody else's action counts and every reward is 0.
2. **act move**: environment (dynamics/force) adversaries set the simulator, protagonists act
   on what they were shown, action adversaries perturb those actions, the simulator steps,
   reward/cost adversaries perturb what the learners observe. Protagonists receive the
   *observed* reward; every adversary receives ``-payoff``, the negative of the protagonists'
   *true* team payoff (``true_reward - cost_weight * true_cost``).

Before the first step of an episode, workspace adversaries (reset-time disruptors such as
`WorkspaceDisruptor`: table, door and object placement, colours) play a *setup move* of their own
(a sense-kind move: reward 0, protagonists' actions ignored): they observe the nominal ``s_0``,
edit the simulator, and everyone then observes the disturbed ``s_0``.

Every agent submits an action on every move (the ParallelEnv contract); `Game.next_movers` says
whose action the next move uses, and ``infos[agent]["acted"]`` says whose action counted in the
move just made. Observations returned by an act move that is followed by a sense move are the
true next state; the protagonists act on the perturbed one the sense move returns.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from advgame.core.disruptor import Disruptor, DisruptorSpec
from advgame.core.moves import (
    ACT,
    SENSE,
    Hooks,
    Move,
    missing_or_unknown,
    package,
)
from advgame.core.moving import Moves
from advgame.core.mujoco_timers import quiet_timers
from advgame.core.policy import AgentInfo
from advgame.core.schedule import PHASES, Schedule
from advgame.core.task import TaskBase
from advgame.errors import ActionError, ConfigError, UnsupportedError, did_you_mean

__all__ = ["Game", "Move"]

log = logging.getLogger(__name__)


class Game(Moves, ParallelEnv):
    """A PettingZoo ParallelEnv of protagonists against bounded adversary agents.

    Build one with `advgame.make`.

    Args:
        task: the task base.
        disruptors: disruptor specs; each becomes one adversary agent.
        cost_weight: weight of the true cost in the payoff adversaries are paid on.
        phase: ``"train"`` or ``"eval"``; disruptors whose schedule is for the other phase are
            the identity (the paper's in-training / post-training settings).
        scenario_id: the registry id, for `repr` and reports.

    """

    def __init__(
        self,
        task: TaskBase,
        disruptors: Sequence[DisruptorSpec] = (),
        *,
        cost_weight: float = 0.0,
        phase: str = "train",
        scenario_id: str = "",
    ) -> None:
        self.task = task
        self.scenario_id = scenario_id
        self.metadata: dict[str, Any] = {
            "name": "advgame_v0",
            "is_parallelizable": True,
            "render_modes": _render_modes(task),
        }
        """PettingZoo's metadata; ``render_modes`` are the task base's own (none: state-only)."""
        self.render_mode: str | None = getattr(getattr(task, "env", None), "render_mode", None)
        """The task base's render mode (``make(..., render_mode=...)``); None: `render` refuses."""
        self.preset: Any = None
        """The `Preset` the game was made from, if any (set by `advgame.make`)."""
        if not np.isfinite(cost_weight) or cost_weight < 0:
            raise ConfigError(f"cost_weight must be finite and >= 0, got {cost_weight!r}.")
        if cost_weight > 0 and not getattr(task, "has_cost", False):
            raise ConfigError(
                f"cost_weight={cost_weight!r}, but {type(task).__name__} "
                f"{scenario_id or ''} computes no cost; use a safe scenario "
                "(advgame.list_scenarios(family='safe')) or leave cost_weight at 0."
            )
        self.cost_weight = float(cost_weight)
        self.protagonists: tuple[str, ...] = tuple(task.protagonists)
        self.disruptors: dict[str, Disruptor] = {}
        for spec in disruptors:
            if not isinstance(spec, DisruptorSpec):
                raise ConfigError(f"Expected a DisruptorSpec, got {type(spec).__name__}: {spec!r}.")
            if spec.agent in self.disruptors or spec.agent in self.protagonists:
                raise ConfigError(
                    f"Two agents are named {spec.agent!r}; give one disruptor a distinct name=..."
                )
            self.disruptors[spec.agent] = spec.build(task)
        self.adversaries: tuple[str, ...] = tuple(self.disruptors)
        self.possible_agents = [*self.protagonists, *self.adversaries]
        self.agents: list[str] = []
        self._all = frozenset(self.possible_agents)
        self._obs_spaces = {
            **task.observation_spaces,
            **dict.fromkeys(self.adversaries, task.state_space),
        }
        self._act_spaces = {
            **task.action_spaces,
            **{a: d.action_space for a, d in self.disruptors.items()},
        }
        self.observation_spaces = {a: self._obs_spaces[a] for a in self.possible_agents}
        self.action_spaces = {a: self._act_spaces[a] for a in self.possible_agents}
        self._p_spaces: dict[str, tuple[spaces.Space, tuple[int, ...] | None]] = {}
        for p in self.protagonists:  # in protagonist order; shape None: a Discrete action
            s = task.action_spaces[p]
            self._p_spaces[p] = (s, None if isinstance(s, spaces.Discrete) else s.shape)
        hooks = Hooks.of(self.disruptors.values())
        self._sensing, self._stale, self._setup_ds = hooks.sensing, hooks.stale, hooks.setup
        self._action_ds, self._reward_ds = hooks.action, hooks.reward
        self._model_ds, self._data_ds = hooks.model, hooks.data
        self._env_ds = self._model_ds + self._data_ds
        self._act_ds = [*self._env_ds, *self._action_ds, *self._reward_ds, *self._stale]
        self._held_sensing = [d for d in self._sensing if d.schedule.hold]
        self._scaled = [
            d
            for d in self._sensing + self._stale
            if getattr(d.spec, "space", "raw") == "normalized"
        ]
        self._constant: dict[str, bool] = {}
        self._dynamic: list[tuple[str, Schedule]] = []
        self._fixed_movers = (frozenset[str](), frozenset[str]())
        self._phase = ""
        self.phase = phase
        self._rng = np.random.default_rng()
        self._last: dict[str, np.ndarray] = {}
        self._active: dict[str, bool] = {}
        self.move = ACT
        self.t = 0
        self.next_movers: frozenset[str] = frozenset()
        self._act_next: frozenset[str] = frozenset()
        self._true_obs: dict[str, Any] = {}
        self._shown: dict[str, Any] = {}
        self._state: Any = None
        self._setup_pending = False
        self._after_setup: tuple[str, frozenset[str]] = (ACT, frozenset())
        self.last_reward = 0.0
        """The protagonists' true team reward of the last act move (0 before the first)."""
        self.episode_reward = 0.0
        """The true team reward summed over this episode so far (what LLM prompts report)."""

    def agent_info(self, agent: str) -> AgentInfo:
        """Spaces (and disruptor) of `agent`, what a `PolicySpec` needs to build its policy."""
        return AgentInfo(
            agent,
            self.observation_space(agent),
            self.action_space(agent),
            self.disruptors.get(agent),
        )

    def set_observation_scale(self, target: str, std: Any) -> int:
        """Give normalized-space observation disruptors on `target` its normalizer's std.

        ATLA budgets live in the protagonist's normalized observation space; the training loop
        calls this with the (frozen) running std. Returns how many disruptors were updated.
        """
        count = 0
        for d in self._scaled:
            if target in d.targets:  # type: ignore[attr-defined]
                d.set_scale(target, std)  # type: ignore[attr-defined]
                count += 1
        return count

    @property
    def scaled_targets(self) -> list[str]:
        """The protagonists observed through normalized-space budgets (`set_observation_scale`)."""
        return sorted({t for d in self._scaled for t in d.targets})  # type: ignore[attr-defined]

    # -- PettingZoo surface -----------------------------------------------------------------
    def observation_space(self, agent: str) -> spaces.Space:
        """Protagonists: the task's observation space; adversaries: the true-state space."""
        return self._obs_spaces[self._known(agent)]

    def action_space(self, agent: str) -> spaces.Space:
        """Protagonists: the task's action space; adversaries: their disruptor's bounded Box."""
        return self._act_spaces[self._known(agent)]

    @property
    def state_space(self) -> spaces.Space:
        """The space of `state()`, the true global state."""
        return self.task.state_space

    def state(self) -> Any:
        """The true global state ``s_t`` (what adversaries observe)."""
        return self._state

    @property
    def phase(self) -> str:
        """``"train"`` or ``"eval"``: which schedules are live."""
        return self._phase

    @phase.setter
    def phase(self, value: str) -> None:
        if value not in PHASES[:2]:
            raise ConfigError(f"phase must be 'train' or 'eval', got {value!r}.")
        self._phase = value
        self._plan_schedules()

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Start an episode: restore nominal parameters, reset the task, draw the first schedule.

        ``options={"phase": "eval"}`` switches the phase; other keys are ignored.
        """
        if seed is not None:
            self._rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xAD6A]))
        if options and "phase" in options:
            self.phase = options["phase"]
        self._restore_environment()
        for d in self.disruptors.values():
            d.reset()
        obs, info = self.task.reset(seed)
        quiet_timers()  # the task may have made an MjData, which sets MuJoCo's timers again
        self.t = 0
        self.agents = list(self.possible_agents)
        self._last = {}
        self._setup_pending = bool(self._setup_ds)
        self.last_reward = self.episode_reward = 0.0
        self._begin_step(obs, pending=None)
        observations = {**self._shown, **dict.fromkeys(self.adversaries, self._state)}
        infos: dict[str, dict] = {a: {} for a in self.agents}
        for p in self.protagonists:
            infos[p] = dict(info)
        return observations, infos

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Make one move (PettingZoo form); see the module docstring for sense and act moves."""
        if not self.agents:
            raise ActionError("The episode is over (no live agents); call reset() before step().")
        if actions.keys() != self._all:
            raise missing_or_unknown(actions, self._all, self.agents, self.possible_agents)
        m = self._sense(actions) if self.move == SENSE else self._act(actions)
        return package(m, self.protagonists, self.adversaries, self._shown, self._state)

    def play(self, actions: Mapping[str, Any]) -> Move:
        """Make one move, lean form: `actions` needs only the agents in `next_movers`.

        Same semantics as `step` without building the per-agent dicts; rollouts and
        single-agent views use it. Current observations: `observe`.
        """
        if not (self.agents and actions.keys() >= self.next_movers):
            self.require(actions.keys())  # raises, and says why
        if self.move == SENSE:
            return self._sense(actions)
        return self._act(actions)

    def require(self, agents: Any) -> None:
        """Check that a move with actions for `agents` can be made now (`play`'s precondition).

        Raises:
            ActionError: the episode is over, or an agent of `next_movers` is missing.

        """
        if not self.agents:
            raise ActionError("The episode is over (no live agents); call reset() before play().")
        if not agents >= self.next_movers:
            missing = sorted(self.next_movers - set(agents))
            raise ActionError(
                f"This {self.move} move needs actions for {missing} (game.next_movers)."
            )

    def observe(self, agent: str) -> Any:
        """What `agent` observes now: protagonists the (perturbed) observation, adversaries ``s_t``."""
        return self._shown[agent] if agent in self._shown else self._state

    def true_observation(self, agent: str) -> Any:
        """Protagonist `agent`'s true observation at the current step (before any disruptor).

        White-box attacks read it in the sense move: the observation adversary sees ``s_t``.
        """
        if agent not in self.protagonists:
            raise ConfigError(f"{agent!r} is not a protagonist; protagonists: {self.protagonists}.")
        return self._true_obs[agent]

    def render(self) -> Any:
        """Render the task base, as the game's `render_mode` says.

        Raises:
            UnsupportedError: the game was made without a render mode, or its task base has
                none (a state-only task); the message names the scenario and the fix.

        """
        if self.render_mode is None:
            name = self.scenario_id or type(self.task).__name__
            modes = self.metadata["render_modes"]
            fix = (
                f"make it with advgame.make({name!r}, render_mode=...), one of {modes}"
                if modes
                else "its task base offers no render modes (a state-only task); "
                "observations are its only output"
            )
            raise UnsupportedError(f"{name} cannot render: {fix}.")
        return self.task.render()

    def close(self) -> None:
        """Close the task base."""
        self.task.close()

    def _known(self, agent: str) -> str:
        if agent not in self._obs_spaces:
            raise ActionError(
                f"Unknown agent {agent!r}.{did_you_mean(agent, self.possible_agents)} "
                f"Agents of this game: {self.possible_agents}."
            )
        return agent

    def __str__(self) -> str:
        return repr(self)

    def __repr__(self) -> str:
        return (
            f"Game({self.scenario_id or type(self.task).__name__!r}, protagonists="
            f"{list(self.protagonists)}, adversaries={list(self.adversaries)}, phase={self.phase!r})"
        )


def _render_modes(task: TaskBase) -> list[str]:
    """The render modes the task base's simulator lists (none when it lists none)."""
    metadata = getattr(getattr(task, "env", None), "metadata", None)
    modes = metadata.get("render_modes") if isinstance(metadata, Mapping) else None
    return [str(m) for m in modes] if isinstance(modes, (list, tuple)) else []
