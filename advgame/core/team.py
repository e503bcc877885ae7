"""The protagonist team of a game as a PettingZoo `ParallelEnv`, every adversary frozen inside it.

`TeamView` is the multi-agent sibling of `advgame.core.views.SingleAgentView`: its agents are all the
protagonists of a game (MaMuJoCo's ``"agent_0"``, ``"agent_1"``, ...), and every adversary plays
an embedded policy. One `TeamView.step` is one protagonist step of the Disrupted-MDP: the act
move the protagonists' actions count in, then any sense move before their next decision (the
observation adversaries choose ``δ`` on the true state ``s_{t+1}``), so the observations returned
are the (perturbed) ones the protagonists act on next, and `TeamView.state` is the true global
state ``s_{t+1}`` a centralised critic may use.

Multi-agent learners (`advgame.agents.marl.marl`) train on it; with homogeneous agents it also runs
under SuperSuit's padding and agents-as-envs vectorisation (one shared policy for the team).
Under subprocess vectorisation, build views in the workers with `team_factory`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from gymnasium import spaces
from pettingzoo import ParallelEnv

from advgame.core.episodes import (
    build_policies,
    reseed_policies,
    resume_schedules,
    schedule_positions,
)
from advgame.core.game import Game, Move
from advgame.errors import ActionError, ConfigError

__all__ = ["TeamView", "team_factory"]

_MAX_SENSE_MOVES = 16
"""Adversary-only moves allowed between two protagonist decisions (the game makes at most one)."""


class TeamView(ParallelEnv):
    """The protagonists of `game` as a ParallelEnv; adversaries play their policy in `policies`.

    Adversaries missing from `policies` play their no-op (the nominal task); protagonists must not
    be given (they are the learners). Every protagonist is live for the whole episode and all end
    it together (MaMuJoCo ends an episode for the whole team).

    Rewards are what each protagonist *observes* (after any reward disruptor). Each agent's info
    is its own dict: the task's info, the observed ``cost``, and the step's true team
    ``true_reward``, ``true_cost`` and ``payoff`` (what evaluation and the loop report).

    Example:
        >>> import advgame
        >>> game = advgame.make("MA-HalfCheetah-2x3", preset="partial")
        >>> team = TeamView(game)
        >>> obs, infos = team.reset(seed=0)
        >>> team.agents, obs["agent_0"].shape, team.state().shape
        (['agent_0', 'agent_1'], (12,), (17,))

    """

    metadata: ClassVar[dict[str, Any]] = {
        "name": "advgame_team_v0",
        "is_parallelizable": True,
        "render_modes": ["rgb_array", "human"],
    }

    def __init__(self, game: Game, policies: Mapping[str, Any] | None = None) -> None:
        self.game = game
        self.possible_agents: list[str] = list(game.protagonists)
        self.agents: list[str] = []
        self.observation_spaces = {a: game.observation_space(a) for a in self.possible_agents}
        self.action_spaces = {a: game.action_space(a) for a in self.possible_agents}
        self.render_mode = getattr(getattr(game.task, "env", None), "render_mode", None)
        self.policies: dict[str, Any] = {}
        self.set_policies(policies or {})

    # -- PettingZoo surface -----------------------------------------------------------------
    def observation_space(self, agent: str) -> spaces.Space:
        """The protagonist's observation space (the game's cached object)."""
        return self.observation_spaces[self._known(agent)]

    def action_space(self, agent: str) -> spaces.Space:
        """The protagonist's action space (the game's cached object)."""
        return self.action_spaces[self._known(agent)]

    @property
    def state_space(self) -> spaces.Space:
        """The space of `state`, the true global state."""
        return self.game.state_space

    def state(self) -> Any:
        """The true global state at the protagonists' current decision (or the episode's end)."""
        return self.game.state()

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Reset the game and the embedded policies; play until the protagonists' first decision.

        A seed also seeds every embedded policy (each its own stream derived from `seed`).
        """
        reseed_policies(self.policies, seed)
        _, game_infos = self.game.reset(seed=seed, options=options)
        self._advance()
        self.agents = list(self.possible_agents)
        observations = {a: self.game.observe(a) for a in self.agents}
        return observations, {a: dict(game_infos[a]) for a in self.agents}

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """One protagonist step: the act move, then the sense move (if any) before the next one."""
        if not self.agents:
            raise ActionError("The episode is over (no live agents); call reset() before step().")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ActionError(
                f"step() needs an action for every protagonist {self.agents}; missing {missing}."
            )
        game = self.game
        moves = self._adversary_actions()
        moves.update({a: actions[a] for a in self.agents})
        move = game.play(moves)
        if move.rewards is None:  # only possible if the view's invariant broke
            raise ActionError(f"Expected an act move, the game made a {move.kind} move.")
        self._advance()
        agents = self.agents
        if move.terminated or move.truncated:
            self.agents = []
        return (
            {a: game.observe(a) for a in agents},
            {a: float(move.rewards[a]) for a in agents},
            dict.fromkeys(agents, bool(move.terminated)),
            dict.fromkeys(agents, bool(move.truncated)),
            {a: _info(move, a) for a in agents},
        )

    def render(self) -> Any:
        """Render the game's task base."""
        return self.game.render()

    def close(self) -> None:
        """Close the game."""
        self.game.close()

    # -- what the training loop calls -------------------------------------------------------
    def schedule_positions(self) -> dict[str, int]:
        """Where each embedded per-episode schedule is (`advgame.core.episodes.schedule_positions`)."""
        return schedule_positions(self.policies)

    def resume_schedules(self, positions: Mapping[str, int]) -> None:
        """Go on after `positions` (`advgame.core.episodes.resume_schedules`)."""
        resume_schedules(self.policies, positions)

    def set_policies(self, policies: Mapping[str, Any]) -> None:
        """Swap some embedded adversary policies (policies, specs or callables).

        Adversaries not named keep their current policy (initially their no-op).
        """
        mine = set(policies) & set(self.possible_agents)
        if mine:
            raise ConfigError(
                f"{sorted(mine)} are protagonists, the learners of this view; "
                "pass policies for adversaries only."
            )
        probe: dict[str, Any] = dict.fromkeys(self.possible_agents, _Placeholder())
        probe.update(self.policies)
        probe.update(policies)
        built = build_policies(self.game, probe)
        for a in self.game.adversaries:
            if a in policies or a not in self.policies:
                self.policies[a] = built[a]

    def set_observation_scale(self, target: str, std: Any) -> int:
        """Set `target`'s normalizer std for normalized-space observation budgets.

        Returns how many disruptors were updated (`Game.set_observation_scale`).
        """
        return self.game.set_observation_scale(target, std)

    # -- helpers ----------------------------------------------------------------------------
    def _adversary_actions(self) -> dict[str, Any]:
        game = self.game
        return {
            a: self.policies[a].act(game.observe(a)) for a in game.next_movers if a in self.policies
        }

    def _advance(self) -> None:
        """Play adversary-only (sense) moves until the protagonists decide or the episode ends."""
        game, first = self.game, self.possible_agents[0]
        for _ in range(_MAX_SENSE_MOVES):
            if not game.agents or first in game.next_movers:
                return
            game.play(self._adversary_actions())
        raise ActionError(
            f"The protagonists got no decision in {_MAX_SENSE_MOVES} moves; check the schedules."
        )

    def _known(self, agent: str) -> str:
        if agent not in self.observation_spaces:
            game_agent = agent in self.game.possible_agents
            raise ConfigError(
                f"{agent!r} is not a protagonist of this team view"
                + (" (it is an adversary, embedded as a policy)." if game_agent else ".")
                + f" Agents: {self.possible_agents}."
            )
        return agent

    def __repr__(self) -> str:
        return f"TeamView({self.game!r})"


def _info(move: Move, agent: str) -> dict[str, Any]:
    """One protagonist's info dict for an act move (a fresh dict per agent)."""
    assert move.info is not None and move.costs is not None
    return {
        **move.info,
        "cost": move.costs[agent],
        "true_reward": move.reward,
        "true_cost": move.cost,
        "payoff": move.payoff,
    }


class _Placeholder:
    """Stands in for a protagonist while the adversaries' policies are built."""

    def reset(self, seed: int | None = None) -> None:
        """Unused."""

    def act(self, observation: Any) -> Any:
        """Unused."""
        raise AssertionError("a protagonist's placeholder policy is never queried")


def _build_team(
    scenario_id: str, policies: Mapping[str, Any], make_kwargs: Mapping[str, Any]
) -> TeamView:
    from advgame.core.registry import make

    return TeamView(make(scenario_id, **make_kwargs), policies)


def team_factory(
    scenario_id: str, policies: Mapping[str, Any] | None = None, **make_kwargs: Any
) -> Callable[[], TeamView]:
    """A picklable thunk that builds the game and its `TeamView` (in any process).

    `policies` (adversary id -> policy spec) must be picklable; `make_kwargs` go to
    `advgame.make` (``preset``, ``phase``, ``max_episode_steps``, ...).

    Example:
        >>> team = team_factory("MA-HalfCheetah-2x3", preset="default")()
        >>> team.possible_agents
        ['agent_0', 'agent_1']

    """
    return functools.partial(_build_team, scenario_id, dict(policies or {}), dict(make_kwargs))
