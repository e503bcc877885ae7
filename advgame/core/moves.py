"""What one move of a `Game` produces, and the checks and packaging around it.

`Move` is the lean outcome `Game.play` returns; `package` turns it into PettingZoo's five
per-agent dicts (`Game.step`). `protagonist_action` validates what a protagonist sends and
`missing_or_unknown` words the error for an action dict with the wrong agents.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from gymnasium import spaces

from advgame.core.checks import all_finite
from advgame.errors import ActionError, did_you_mean

if TYPE_CHECKING:
    from advgame.core.disruptor import Disruptor

__all__ = [
    "ACT",
    "SENSE",
    "Hooks",
    "Move",
    "missing_or_unknown",
    "package",
    "protagonist_action",
]

SENSE, ACT = "sense", "act"


@dataclass(frozen=True)
class Hooks:
    """A game's disruptors grouped by where in a step they act (built once per game)."""

    sensing: list[Disruptor]
    """Observation disruptors that move in the sense move (they see ``s_t`` first)."""
    stale: list[Disruptor]
    """Observation disruptors with ``timing="stale"`` (they move with the protagonist)."""
    action: list[Disruptor]
    """Action disruptors."""
    reward: list[Disruptor]
    """Reward and cost disruptors."""
    setup: list[Disruptor]
    """Environment disruptors that act once, in the setup move at t = 0 (workspace)."""
    model: list[Disruptor]
    """Environment disruptors that edit the model each step (dynamics; may recompile it)."""
    data: list[Disruptor]
    """Environment disruptors that edit the simulation data each step (forces)."""

    @classmethod
    def of(cls, disruptors: Iterable[Disruptor]) -> Hooks:
        """Group `disruptors` by hook, timing and what they edit."""
        by_hook: dict[str, list[Disruptor]] = {h: [] for h in ("observation", "action", "reward")}
        by_hook["environment"] = []
        for d in disruptors:
            by_hook[d.hook].append(d)
        obs, env = by_hook["observation"], by_hook["environment"]
        stepped = [d for d in env if not getattr(d, "at_reset", False)]
        return cls(
            sensing=[d for d in obs if getattr(d, "timing", "sense") == "sense"],
            stale=[d for d in obs if getattr(d, "timing", "sense") == "stale"],
            action=by_hook["action"],
            reward=by_hook["reward"],
            setup=[d for d in env if getattr(d, "at_reset", False)],
            model=[d for d in stepped if getattr(d, "edits_model", False)],
            data=[d for d in stepped if not getattr(d, "edits_model", False)],
        )


@dataclass(slots=True)
class Move:
    """The outcome of one move in lean form (`Game.play`)."""

    kind: str
    """``"sense"`` or ``"act"``."""
    clipped: dict[str, int]
    """Adversaries whose action counted in this move -> components clipped into the budget."""
    rewards: dict[str, float] | None = None
    """Act moves: the reward each protagonist observes (after reward disruptors)."""
    costs: dict[str, float] | None = None
    """Act moves: the cost each protagonist observes (after cost disruptors)."""
    reward: float = 0.0
    """Act moves: the true team reward."""
    cost: float = 0.0
    """Act moves: the true team cost."""
    payoff: float = 0.0
    """Act moves: the true payoff ``reward - cost_weight * cost``; adversaries get its negative."""
    terminated: bool = False
    """The episode terminated."""
    truncated: bool = False
    """The episode was truncated."""
    info: dict[str, Any] | None = None
    """Act moves: the task base's info."""


def package(
    m: Move,
    protagonists: Sequence[str],
    adversaries: Sequence[str],
    shown: Mapping[str, Any],
    state: Any,
) -> tuple[dict, dict, dict, dict, dict]:
    """PettingZoo's ``(observations, rewards, terminations, truncations, infos)`` of move `m`.

    Protagonists observe `shown` (their possibly perturbed observations), adversaries the true
    `state`; protagonists get their observed reward, adversaries ``-payoff``.
    """
    infos: dict[str, dict] = {}
    if m.kind == SENSE:
        rewards = dict.fromkeys(protagonists, 0.0)
        adversary_reward = 0.0
        for p in protagonists:
            infos[p] = {"acted": False}
    else:
        assert m.rewards is not None and m.costs is not None and m.info is not None
        rewards, adversary_reward = dict(m.rewards), -m.payoff
        for p in protagonists:
            infos[p] = {
                **m.info,
                "acted": True,
                "true_reward": m.reward,
                "true_cost": m.cost,
                "cost": m.costs[p],
                "payoff": m.payoff,
            }
    obs, clipped = dict(shown), m.clipped
    for a in adversaries:  # plain loops: cheaper than merging dicts
        obs[a] = state
        rewards[a] = adversary_reward
        infos[a] = {"acted": a in clipped, "clipped": clipped.get(a, 0)}
    # `obs` now holds every agent, protagonists first: the order of `possible_agents`
    return obs, rewards, dict.fromkeys(obs, m.terminated), dict.fromkeys(obs, m.truncated), infos


def protagonist_action(
    agent: str, space: spaces.Space, shape: tuple[int, ...] | None, action: Any
) -> Any:
    """`action` checked against `space` (`shape` None: a Discrete space), in its dtype.

    Raises:
        ActionError: not numeric, wrong shape, NaN/inf, or not an int of a Discrete space.

    """
    if shape is None:
        return _discrete_action(agent, space, action)
    a = action if type(action) is np.ndarray else np.asarray(action)
    if a.dtype != space.dtype:
        try:
            a = a.astype(space.dtype)
        except (TypeError, ValueError):
            raise ActionError(
                f"Action for {agent!r} is not numeric: {action!r} ({space})."
            ) from None
    if a.shape != shape:
        raise ActionError(f"Action for {agent!r} has shape {a.shape}; expected {shape} ({space}).")
    if not all_finite(a):
        raise ActionError(f"Action for {agent!r} contains NaN or inf: {a}.")
    return a


def protagonist_rows(
    agent: str, space: spaces.Space, shape: tuple[int, ...] | None, actions: Any
) -> Sequence[Any]:
    """`protagonist_action` of every row of `actions` (N games' actions), checked at once.

    A stack ``[N, *shape]`` of finite values is converted to the space's dtype and checked in
    one pass, and its rows are returned; anything else (a Discrete space, a ragged or
    non-numeric batch, NaN) goes row by row, so each error names the row's own action.
    """
    if shape is not None:
        try:
            a = actions if type(actions) is np.ndarray else np.asarray(actions)
            if a.dtype != space.dtype:
                a = a.astype(space.dtype)
        except (TypeError, ValueError):
            a = None
        if a is not None and a.shape == (len(actions), *shape) and all_finite(a):
            return a  # type: ignore[return-value]  # an array is a sequence of its rows
    return [protagonist_action(agent, space, shape, row) for row in actions]


def _discrete_action(agent: str, space: Any, action: Any) -> np.int64:
    try:
        ok = np.ndim(action) == 0 and float(action) == int(action)
        ok = ok and space.contains(np.int64(action))
    except (TypeError, ValueError, OverflowError):  # None, "left", nan, inf
        ok = False
    if not ok:
        raise ActionError(f"Action for {agent!r} must be an int in {space}, got {action!r}.")
    return np.int64(action)


def missing_or_unknown(
    actions: Mapping[str, Any], expected: frozenset[str], agents: Sequence[str], possible: list[str]
) -> ActionError:
    """The error for an action dict that lacks some of `expected` or names unknown agents."""
    missing = sorted(expected - actions.keys())
    unknown = sorted(set(actions) - expected)
    msg = []
    if missing:
        msg.append(f"missing actions for {missing}")
    if unknown:
        hint = "".join(did_you_mean(u, possible) for u in unknown)
        msg.append(f"actions for unknown agents {unknown}.{hint}")
    return ActionError(
        f"step() needs one action for every live agent {agents}: {'; '.join(msg)}. "
        "Agents whose action does not count this move (see game.next_movers) may send "
        "any valid action, e.g. action_space(agent).sample()."
    )
