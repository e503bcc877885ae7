"""Batched evaluation's array path: the all-live steps of alike episodes on `ArrayGame` objects.

`advgame.core.episodes.rollout_batch` plays one episode in each of its games. After the games
are reset and their policies reseeded, `play_arrays` splits them into groups of alike games
(one scenario and disruptor set-up; the columns of an evaluation table) that the array game can
play (`advgame.core.array_game.unsupported`), builds one `ArrayGame` per group of two or more
and reads each copy's state from its game (`ArrayGame.pull`). Then, step by step, every group:

* makes its sense move where an observation adversary acts, the sensing adversaries' policies
  asked for the copies where each acts;
* makes its act move (protagonists, and the act-move adversaries where each acts);
* adds each copy's move to its `EpisodeResult` as `rollout_batch` adds a `Move`.

Before each move, the policies of all groups that share a ``batch_key`` (the copies of one
frozen network, in every group) are asked at once (`advgame.core.policy.act_batch`, exact).
As soon as an episode of a group ends, every copy of that group is handed back to its game
(`ArrayGame.push`), and `rollout_batch` finishes the remaining live episodes on its lockstep
path. So an episode that never terminates (HalfCheetah) plays whole on arrays, and a
terminating task plays on arrays until its group's first ending.

Games stay on the lockstep path when they are alone in their group, when their task base
cannot batch its simulators (Box2D: both paths would step them one by one), when a policy reads its
game (``policy.game``: white-box attacks, LLM adversaries), or when their phases differ. Games
whose normalized-space budgets have different scales (protagonists behind different
normalizers) go to different groups: the array game applies one copy's disruptors to all rows. Every `EpisodeResult` is that of the lockstep path, bit for bit
(``tests/test_eval_array.py``). `USE_ARRAYS` switches the path off (benchmarks, tests).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from advgame.core.array_game import ArrayGame, unsupported
from advgame.core.lockstep import alike
from advgame.core.policy import Policy, act_batch

if TYPE_CHECKING:
    from advgame.core.game import Game

__all__ = ["USE_ARRAYS", "Tally", "array_groups", "play_arrays"]

log = logging.getLogger(__name__)

USE_ARRAYS = True
"""Whether `rollout_batch` plays alike games on arrays (False: the lockstep path only)."""


class Tally(Protocol):
    """What `play_arrays` adds each move to: an `advgame.core.episodes.EpisodeResult`."""

    true_return: float
    observed_return: float
    cost: float
    payoff: float
    length: int
    clipped: dict[str, int]
    terminated: bool


_Run = tuple[ArrayGame, list[int]]  # an array game and the indices of its copies' games


def array_groups(
    games: Sequence[Game], policies: Sequence[Mapping[str, Policy]]
) -> list[list[int]]:
    """The indices of `games` that `play_arrays` plays as one `ArrayGame` each (groups of >= 2).

    Games are grouped when alike (`advgame.core.lockstep.alike`) with equal scales of their
    normalized-space budgets (each protagonist's ``observation_std``); a group the array game cannot
    play, or whose policies or budgets forbid it (see the module docstring), is left out, and
    why is logged at debug level. Empty when `USE_ARRAYS` is False.
    """
    if not USE_ARRAYS or len(games) < 2:
        return []
    by: list[list[int]] = []
    for k, game in enumerate(games):
        if not game.agents:
            continue
        for idx in by:
            if _scaled_alike(games[idx[0]], game) and alike([games[idx[0]], game]):
                idx.append(k)
                break
        else:
            by.append([k])
    out = []
    for idx in by:
        reason = _why_not([games[k] for k in idx], [policies[k] for k in idx])
        if reason is None:
            out.append(idx)
        else:
            log.debug(
                "rollout_batch plays %d games in lockstep, not as arrays: %s.", len(idx), reason
            )
    return out


def _why_not(games: Sequence[Game], policies: Sequence[Mapping[str, Policy]]) -> str | None:
    if len(games) < 2:
        return "one game plays alone"
    reason = unsupported(games)
    if reason is not None:
        return reason
    if not type(games[0].task).batched:  # the lockstep path steps them one by one, quietly
        return f"{type(games[0].task).__name__} cannot batch its simulators"
    if len({g.phase for g in games}) > 1:
        return "the games play different phases"
    for pols in policies:
        for a, p in pols.items():
            if getattr(p, "game", None) is not None:
                return f"the policy of {a!r} reads its game ({type(p).__name__})"
    if not all(_scaled_alike(games[0], g) for g in games[1:]):
        return "their normalized-space budgets have different scales"
    return None


def _scaled_alike(a: Game, b: Game) -> bool:
    """Whether the normalized-space budgets of `a` and `b` have equal scales (or neither has)."""
    if len(a._scaled) != len(b._scaled):
        return False
    for da, db in zip(a._scaled, b._scaled, strict=True):
        sa, sb = getattr(da, "scale", None) or {}, getattr(db, "scale", None) or {}
        if sa.keys() != sb.keys() or not all(np.array_equal(sa[t], sb[t]) for t in sa):
            return False
    return True


def play_arrays(
    games: Sequence[Game],
    policies: Sequence[Mapping[str, Policy]],
    keys: Sequence[Mapping[str, Any]],
    results: Sequence[Tally],
) -> None:
    """Play the steps of `games` (just reset) on arrays while every copy of a group is live.

    ``policies[k]`` plays game ``k`` and ``keys[k]`` groups its policies by batch key (as
    `rollout_batch` groups them); each move is added to ``results[k]``. On return, every game
    holds its own state again, at the start of a step (its sense move, if any, still to come).
    """
    runs: list[_Run] = []
    for idx in array_groups(games, policies):
        array = ArrayGame([games[k] for k in idx])
        for i in range(array.n):
            array.pull(i)
        runs.append((array, idx))
    while runs:
        _sense(runs, policies, keys, results)
        actions = _ask(runs, policies, keys, _acting)
        runs = [run for run, acts in zip(runs, actions, strict=True) if _act(run, acts, results)]


def _sensing(array: ArrayGame) -> list[str]:
    return [d.agent for d in array._sensing]


def _acting(array: ArrayGame) -> list[str]:
    return [*array.protagonists, *(d.agent for d in array._act_ds)]


def _sense(
    runs: Sequence[_Run],
    policies: Sequence[Mapping[str, Policy]],
    keys: Sequence[Mapping[str, Any]],
    results: Sequence[Tally],
) -> None:
    """The sense move of every group where an observation adversary acts; clips recorded."""
    sensing = [run for run in runs if run[0].sensing().any()]
    if not sensing:
        return
    for (array, idx), actions in zip(sensing, _ask(sensing, policies, keys, _sensing), strict=True):
        array.sense(actions)
        for a, counts in array.last_clipped.items():
            for k, n in zip(idx, counts.tolist(), strict=True):
                results[k].clipped[a] += n


def _act(run: _Run, actions: dict[str, Any], results: Sequence[Tally]) -> bool:
    """The act move of one group, recorded; whether the group goes on (no episode ended)."""
    array, idx = run
    step = array.act(actions)
    first = array.protagonists[0]
    clipped = {a: c.tolist() for a, c in step.clipped.items()}
    reward, cost, payoff = step.reward.tolist(), step.cost.tolist(), step.payoff.tolist()
    observed, terminated = step.rewards[first].tolist(), step.terminated.tolist()
    for i, k in enumerate(idx):
        res = results[k]
        for a, c in clipped.items():
            res.clipped[a] += c[i]
        res.true_return += reward[i]
        res.cost += cost[i]
        res.payoff += payoff[i]
        res.observed_return += observed[i]
        res.length += 1
        res.terminated = terminated[i]
    if not array.done.any():
        return True
    for i, k in enumerate(idx):  # hand every copy back; the lockstep path finishes the rest
        array.push(i, sensed=False)
        game = array.games[i]
        game.last_reward, game.episode_reward = reward[i], results[k].true_return
    return False


def _ask(
    runs: Sequence[_Run],
    policies: Sequence[Mapping[str, Policy]],
    keys: Sequence[Mapping[str, Any]],
    agents_of: Callable[[ArrayGame], list[str]],
) -> list[dict[str, Any]]:
    """Per group, ``{agent: [N, ...]}``: the actions of `agents_of` where each moves.

    Adversaries are asked only for the copies where they act (their other rows are zeros, which
    the array game ignores). Policies of one batch key are asked at once across all groups.
    """
    groups: dict[Any, list[tuple[int, str, int]]] = {}
    for j, (array, idx) in enumerate(runs):
        for a in agents_of(array):
            on = array._active.get(a)
            rows = range(array.n) if on is None else np.flatnonzero(on).tolist()
            for i in rows:
                groups.setdefault(keys[idx[i]][a], []).append((j, a, i))
    got: list[dict[str, dict[int, Any]]] = [{} for _ in runs]
    for rows in groups.values():
        pols = [policies[runs[j][1][i]][a] for j, a, i in rows]
        obs = [runs[j][0].observe(a)[i] for j, a, i in rows]
        for (j, a, i), action in zip(rows, act_batch(pols, obs, exact=True), strict=True):
            got[j].setdefault(a, {})[i] = action
    out: list[dict[str, Any]] = []
    for (array, _), mine in zip(runs, got, strict=True):
        actions: dict[str, Any] = {}
        for a, by_row in mine.items():  # rows of several batch keys may come in any order
            idx = sorted(by_row)
            actions[a] = array.rows_of(a, idx, [by_row[i] for i in idx])
        out.append(actions)
    return out
