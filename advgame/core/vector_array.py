"""`VectorView`'s array path: N single-agent views stepped through one `ArrayGame`.

When the N views of a `advgame.core.vector.VectorView` are views of alike games the array game
can play (`advgame.core.array_game.unsupported`), of a protagonist or of an adversary that moves
on every step, and none of their embedded policies reads its game directly (white-box attacks
and LLM adversaries are bound to their game), `ArrayPath` steps them as one `ArrayGame`: the
embedded policies of each agent are asked once for the copies where it moves
(`advgame.core.policy.act_batch`), the moves are the array game's, and each view's reward and
info are the ones its own `SingleAgentView.step` returns (the same sums in the same order).
Resets stay each view's own (`SingleAgentView.reset`: seeds, the policies' reseeding, the moves
before the learner's first decision), after which the array game reads the copy's state back
(`ArrayGame.pull`). Anything else takes the lockstep path.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import numpy as np

from advgame.core.array_game import ArrayGame, ArrayStep, unsupported
from advgame.core.checks import all_set, any_set
from advgame.core.policy import act_batch
from advgame.core.views import SingleAgentView

__all__ = ["ArrayPath", "array_path"]

log = logging.getLogger(__name__)


def array_path(views: Sequence[SingleAgentView], exact: bool) -> ArrayPath | None:
    """An `ArrayPath` over `views`, or None (logged at debug level, with why) when it cannot."""
    reason = _why_not(views)
    if reason is not None:
        log.debug("VectorView steps its views in lockstep, not as arrays: %s.", reason)
        return None
    return ArrayPath(views, exact)


def _why_not(views: Sequence[SingleAgentView]) -> str | None:
    games = [v.game for v in views]
    if len(views) < 2:
        return "one view steps itself"
    reason = unsupported(games)
    if reason is not None:
        return reason
    agent, g0 = views[0].agent, games[0]
    d = g0.disruptors.get(agent)
    if d is not None and d.schedule.constant(g0.phase) is not True:
        return f"the learner {agent!r} does not move on every step"
    for v in views:
        for a, p in v.policies.items():
            if getattr(p, "game", None) is not None:
                return f"the embedded policy of {a!r} reads its game ({type(p).__name__})"
    return None


class ArrayPath:
    """Steps `views` (a `VectorView`'s) through one `ArrayGame` (see the module docstring)."""

    def __init__(self, views: Sequence[SingleAgentView], exact: bool) -> None:
        self.views = list(views)
        self.exact = exact
        self.game = ArrayGame([v.game for v in views])
        g0 = views[0].game
        self.agent = views[0].agent
        self._protagonist = self.agent in g0.protagonists
        self._sensing = [d.agent for d in g0._sensing]
        self._acting = [*g0.protagonists, *(d.agent for d in g0._act_ds)]
        self._senses = self.agent in self._sensing
        self._adversary_info = ("clipped", "true_reward", "true_cost", "payoff")

    def push(self) -> None:
        """Hand every copy back to its own game (the views then step in lockstep)."""
        for i in range(self.game.n):
            self.game.push(i, sensed=not self._senses)

    def pulled(self, i: int) -> None:
        """View `i` was reset on its own (its game is at the learner's decision): read it."""
        self.game.pull(i)

    def step(self, actions: Any) -> list[tuple[Any, float, bool, bool, dict]]:
        """One decision of every view's learner: each view's ``(obs, reward, ends, info)``."""
        game, agent = self.game, self.agent
        clipped = None
        if self._senses:  # the learner's own sense move, then the act move of the others
            self._sense({agent: np.asarray(actions)})
            clipped = game.last_clipped[agent].copy()
            step = game.act(self._ask(self._acting))
        else:
            step = game.act({**self._ask(self._acting), agent: actions})
            if agent in step.clipped:
                clipped = step.clipped[agent]
        if not self._senses and any_set(game.sensing() & ~game.done):
            self._sense({})  # the next step's sense move, of the embedded adversaries
        return self._results(step, clipped)

    def _sense(self, given: dict[str, Any]) -> None:
        game = self.game
        live = ~game.done
        actions = {**self._ask([a for a in self._sensing if a not in given], live), **given}
        game.sense(actions, rows=live)

    def _ask(self, agents: Sequence[str], live: np.ndarray | None = None) -> dict[str, Any]:
        """The embedded policies' actions of `agents` for the copies where each moves."""
        game, out = self.game, dict[str, Any]()
        for a in agents:
            if a == self.agent:
                continue
            rows = game.active(a) if a in game.disruptors else np.ones(game.n, np.bool_)
            if live is not None:
                rows &= live
            if not any_set(rows):
                continue
            obs = game.observe(a)
            if all_set(rows):  # every copy moves (the common case): no index arrays
                policies = [v.policies[a] for v in self.views]
                out[a] = act_batch(policies, list(obs), self.exact)  # rows as obs[i] gives them
                continue
            idx = np.flatnonzero(rows)
            answers = act_batch(
                [self.views[i].policies[a] for i in idx], [obs[i] for i in idx], self.exact
            )
            out[a] = game.rows_of(a, idx, answers)
        return out

    def _results(
        self, step: ArrayStep, clipped: np.ndarray | None
    ) -> list[tuple[Any, float, bool, bool, dict]]:
        """Each view's ``(obs, reward, terminated, truncated, info)`` of this step."""
        game, agent = self.game, self.agent
        obs = (
            game.observe(agent) if self._protagonist else game.state()
        ).copy()  # rows outlive resets
        out = []
        term, trunc = step.terminated.tolist(), step.truncated.tolist()
        if self._protagonist:
            rewards, costs = step.rewards[agent].tolist(), step.costs[agent].tolist()
            true_r, true_c, pay = step.reward.tolist(), step.cost.tolist(), step.payoff.tolist()
            info_rows = [
                dict(zip(step.info, row, strict=True))
                for row in zip(*step.info.values(), strict=True)
            ]
            if not info_rows:
                info_rows = [{} for _ in range(game.n)]
            for i in range(game.n):
                info = info_rows[i]
                get = info.get
                info["cost"] = get("cost", 0.0) + costs[i]
                info["true_reward"] = get("true_reward", 0.0) + true_r[i]
                info["true_cost"] = get("true_cost", 0.0) + true_c[i]
                info["payoff"] = get("payoff", 0.0) + pay[i]
                out.append((obs[i], 0.0 + rewards[i], term[i], trunc[i], info))
            return out
        counts = [0] * game.n if clipped is None else clipped.tolist()
        for i, (r, c, p) in enumerate(
            zip(step.reward.tolist(), step.cost.tolist(), step.payoff.tolist(), strict=True)
        ):
            info = {"clipped": 0 + counts[i], "true_reward": 0.0 + r}
            info["true_cost"], info["payoff"] = 0.0 + c, 0.0 + p
            out.append((obs[i], 0.0 - p, term[i], trunc[i], info))
        return out
