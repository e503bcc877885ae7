"""Play whole episodes of a game with one policy per agent, and what they measure (`rollout`).

This is the evaluation primitive: a `Policy` (or spec, or callable) per agent, a seed, an
`EpisodeResult` with the protagonists' *true* return (what robust metrics are computed on),
their observed return, and each adversary's clip count. `rollout_batch` plays many episodes at
once: alike games on arrays while all their episodes are live (`advgame.core.array_rollout`),
the rest in lockstep (`advgame.core.lockstep`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from gymnasium import spaces

from advgame.core import lockstep
from advgame.core.array_rollout import play_arrays
from advgame.core.policy import ConstantPolicy, Policy, as_policy
from advgame.errors import ConfigError

if TYPE_CHECKING:
    from advgame.core.game import Game

__all__ = [
    "EpisodeResult",
    "build_policies",
    "filler_action",
    "reseed_policies",
    "resume_schedules",
    "rollout",
    "rollout_batch",
    "schedule_positions",
]


@dataclass
class EpisodeResult:
    """What one episode measured."""

    true_return: float = 0.0
    """Sum of the true team reward."""
    observed_return: float = 0.0
    """Sum of the reward the first protagonist observed (after any reward disruptor)."""
    cost: float = 0.0
    """Sum of the true team cost."""
    payoff: float = 0.0
    """Sum of the zero-sum payoff (reward - cost_weight * cost); adversaries got its negative."""
    length: int = 0
    """Protagonist steps (act moves)."""
    clipped: dict[str, int] = field(default_factory=dict)
    """Adversary action components clipped into the budget, per adversary."""
    terminated: bool = False
    """Whether the episode ended by termination rather than truncation."""


def filler_action(space: spaces.Space) -> Any:
    """A fixed valid action for a move in which the agent's action does not count."""
    if isinstance(space, spaces.Discrete):
        return np.int64(space.start)
    if isinstance(space, spaces.Box):
        return np.clip(np.zeros(space.shape, dtype=space.dtype), space.low, space.high)
    return space.sample()


def build_policies(
    game: Game, policies: Mapping[str, Any], default: str = "noop"
) -> dict[str, Policy]:
    """One `Policy` per agent of `game`.

    Adversaries not in `policies` get their no-op (the identity) when `default="noop"`;
    protagonists must always be given. Unknown agent ids are an error. An adversary policy with
    an ``attach(game, victims)`` method (a white-box attack) is then given the game and the
    protagonist policies built here.
    """
    unknown = set(policies) - set(game.possible_agents)
    if unknown:
        raise ConfigError(
            f"Policies given for unknown agents {sorted(unknown)}; agents: {game.possible_agents}."
        )
    out: dict[str, Policy] = {}
    for agent in game.possible_agents:
        info = game.agent_info(agent)
        if agent in policies:
            out[agent] = as_policy(policies[agent], info)
        elif info.disruptor is not None and default == "noop":
            out[agent] = ConstantPolicy(info.noop_action)
        else:
            raise ConfigError(
                f"No policy given for {agent!r}; pass one in policies={{{agent!r}: ...}}."
            )
    victims = {p: out[p] for p in game.protagonists if p in out}
    for agent in game.adversaries:
        attach = getattr(out.get(agent), "attach", None)
        if attach is not None:
            attach(game, victims)
    return out


def reseed_policies(
    policies: Mapping[str, Policy], seed: int | None, index: int | None = None
) -> None:
    """Reset every policy; with a `seed`, each gets its own stream derived from it (in order).

    The one rule rollouts and views share, so an episode seeded the same way plays the same.
    With an episode `index`, a policy that follows a per-episode schedule (it has the optional
    ``set_episode_index``, see `advgame.core.policy.Policy`) is first told to play episode
    `index` of its schedule; without one (training views), it counts its own resets.
    """
    if index is not None:
        for p in policies.values():
            seek = getattr(p, "set_episode_index", None)
            if seek is not None:
                seek(index)
    if seed is None:
        for p in policies.values():
            p.reset(None)
        return
    seeds = np.random.SeedSequence(seed).generate_state(len(policies))
    for s, p in zip(seeds, policies.values(), strict=True):
        p.reset(int(s))


def schedule_positions(policies: Mapping[str, Policy]) -> dict[str, int]:
    """The episode index each per-episode schedule among `policies` plays now (``{agent: i}``).

    Policies with ``episode_index`` and ``set_episode_index`` (`advgame.core.policy.Policy`)
    count. A training checkpoint saves these and `resume_schedules` restores them, so that a
    resumed run's shifting task goes on where it stopped instead of starting its sequence again.
    """
    out = {}
    for agent, p in policies.items():
        where = getattr(p, "episode_index", None)
        if callable(where) and callable(getattr(p, "set_episode_index", None)):
            out[agent] = int(where())
    return out


def resume_schedules(policies: Mapping[str, Policy], positions: Mapping[str, int]) -> None:
    """Make each schedule's next episode the one after its saved position (`schedule_positions`)."""
    for agent, i in positions.items():
        seek = getattr(policies.get(agent), "set_episode_index", None)
        if seek is not None:
            seek(int(i) + 1)


def rollout(
    game: Game,
    policies: Mapping[str, Any],
    seed: int | None = None,
    episodes: int = 1,
    first_index: int | None = None,
) -> list[EpisodeResult]:
    """Play `episodes` episodes; episode ``i`` resets with ``seed + i`` (if a seed is given).

    Each policy is reset with a seed derived from the episode seed, so a seeded rollout is
    reproducible. Only agents in `game.next_movers` are asked to act (`Game.play`). With
    `first_index`, episode ``i`` is episode ``first_index + i`` of every scheduled policy
    (`reseed_policies`); without, scheduled policies count their own resets.

    A protagonist policy that exposes ``observation_std`` (an `SB3Checkpoint` trained behind
    a normalizer) sets the scale of normalized-space observation budgets (ATLA), so a budget
    means the same at evaluation as in training.
    """
    pols = build_policies(game, policies)
    results = []
    for i in range(episodes):
        ep_seed = None if seed is None else seed + i
        index = None if first_index is None else first_index + i
        results += rollout_batch([game], [pols], [ep_seed], [index])
    return results


def rollout_batch(
    games: Sequence[Game],
    policies: Sequence[Mapping[str, Policy]],
    seeds: Sequence[int | None],
    indices: Sequence[int | None] | None = None,
) -> list[EpisodeResult]:
    """Play one episode in each of `games` in lockstep, each the one `rollout` plays alone.

    Game ``k`` plays ``policies[k]`` and resets with ``seeds[k]``; with `indices`, it is
    episode ``indices[k]`` of its scheduled policies (`reseed_policies`). `policies` are built
    policies (`build_policies`), one dict per game, reseeded here. Groups of alike games (one
    scenario and disruptor set-up) that the array game can play first step on one `ArrayGame`
    each until an episode of the group ends (`advgame.core.array_rollout.play_arrays`; off
    when its ``USE_ARRAYS`` is False); then alike games make each move together
    (`advgame.core.lockstep.play_all`). Before each move, the policies of every game in which
    agent ``a`` moves are asked at once (`act_batch`: one forward pass for the copies of a
    frozen network). Either way each result is the one its game plays alone. Random policies must
    keep their randomness to themselves (noise adversaries do); a policy drawing from a global
    generator (a sampling SB3 policy) would see its draws interleaved across games.
    """
    for game, pols in zip(games, policies, strict=True):
        for agent in game.protagonists:
            std = getattr(pols[agent], "observation_std", None)
            if std is not None:
                game.set_observation_scale(agent, std)
    results = []
    order: Sequence[int | None] = [None] * len(games) if indices is None else indices
    for game, pols, seed, index in zip(games, policies, seeds, order, strict=True):
        reseed_policies(pols, seed, index)
        game.reset(seed=seed)
        results.append(EpisodeResult(clipped=dict.fromkeys(game.adversaries, 0)))
    keys = [_batch_keys(pols) for pols in policies]
    play_arrays(games, policies, keys, results)
    same = len(games) > 1 and lockstep.alike(games)
    live = [k for k, game in enumerate(games) if game.agents]
    while live:
        actions = dict(zip(live, _batched_actions(games, policies, keys, live), strict=True))
        for idx in lockstep.groups(games, live):
            agents = actions[idx[0]]  # one group: the same movers
            moves = (lockstep.play_all if same else lockstep.play_each)(
                [games[k] for k in idx], {a: [actions[k][a] for k in idx] for a in agents}
            )
            for k, move in zip(idx, moves, strict=True):
                _record(results[k], move, games[k].protagonists[0])
        live = [k for k in live if games[k].agents]
    return results


def _batch_keys(policies: Mapping[str, Policy]) -> dict[str, Any]:
    """Per agent: what its policy is grouped by (its ``batch_key``, or itself if it has none)."""
    out = {}
    for a, p in policies.items():
        grouped = hasattr(p, "act_batch") or hasattr(p, "act_group")
        key = getattr(p, "batch_key", None) if grouped else None
        out[a] = (a, key) if key is not None else (a, id(p))
    return out


def _batched_actions(
    games: Sequence[Game],
    policies: Sequence[Mapping[str, Policy]],
    keys: Sequence[Mapping[str, Any]],
    live: Sequence[int],
) -> list[dict[str, Any]]:
    """The actions of games `live` for their next move; policies of one batch key asked at once."""
    if len(live) == 1:  # one game: no grouping to do
        game, pols = games[live[0]], policies[live[0]]
        return [{a: pols[a].act(game.observe(a)) for a in game.next_movers}]
    groups: dict[Any, list[tuple[int, str, Any]]] = {}
    for j, k in enumerate(live):
        game, mine = games[k], keys[k]
        for a in game.next_movers:
            groups.setdefault(mine[a], []).append((j, a, game.observe(a)))
    out: list[dict[str, Any]] = [{} for _ in live]
    for rows in groups.values():
        j0, a0, obs0 = rows[0]
        if len(rows) == 1:
            out[j0][a0] = policies[live[j0]][a0].act(obs0)
            continue
        head: Any = policies[live[j0]][a0]  # has act_batch or act_group: a batch key
        obs = np.array([r[2] for r in rows])  # = np.stack, faster
        if hasattr(head, "act_group"):  # each game's own policy state (white-box attacks)
            acts = head.act_group([policies[live[j]][a] for j, a, _ in rows], obs)
        else:
            acts = head.act_batch(obs)
        for (j, a, _), action in zip(rows, acts, strict=True):
            out[j][a] = action
    return out


def _record(res: EpisodeResult, move: Any, first: str) -> None:
    """Add what one move measured to the episode's result."""
    for a, n in move.clipped.items():
        res.clipped[a] += n
    if move.rewards is not None:
        res.true_return += move.reward
        res.cost += move.cost
        res.payoff += move.payoff
        res.observed_return += move.rewards[first]
        res.length += 1
        res.terminated = move.terminated
