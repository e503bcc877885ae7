"""One move of N alike games at once: every check and perturbation once over ``[N, ...]``.

N copies of a scenario stepped in lockstep (`advgame.core.vector.VectorView`, batched
evaluation) spend most of their Python time not in the simulator but in what the game does
around it, once per game: validating and clipping each adversary's action, adding each
observation perturbation, validating each protagonist action. `play_all` makes the move that
every ``games[i].play`` would make with ``actions[agent][i]``, but with those steps done once
for the batch:

* each adversary's ``[N, size]`` actions are decoded by `Disruptor.decode_rows` (one finiteness
  and box test for all rows; a row that fails it is decoded by its own game's disruptor, so
  errors and clip counts are exactly the single game's);
* observation and action perturbations are applied by `Disruptor.observation_rows` and
  `Disruptor.action_rows` as ``[N, dims]`` sums, clips and casts (draw-free modes; the others
  draw from each game's own generator row by row);
* each protagonist's ``[N, *shape]`` actions are checked by `moves.protagonist_rows`.

What stays per game is what is per game: environment disruptors (each game's own model),
rewards, schedules and episode state, through the same `Game` code as a single move
(`Game._after_task`, `Game._begin_step`). The simulator step goes to the task base's
`TaskBase.step_many`, which steps the games' simulators as one batch where the task base can
(Gymnasium MuJoCo tasks: `advgame.scenarios.mujoco_batch.BatchedGymTask`, MuJoCo on a pool of
threads) and game by game otherwise. So every game's move, observation,
reward and clip count are those of its single `play` (``tests/test_lockstep.py``), and one
game is simply N = 1.

Games are *alike* (`alike`) when built from equal disruptor specs on tasks with equal spaces;
`groups` splits them by the move they are about to make.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from advgame.core.game import Game
from advgame.core.moves import ACT, SENSE, Move, protagonist_rows

__all__ = ["alike", "groups", "play_all", "play_each"]


def alike(games: Sequence[Game]) -> bool:
    """Whether the games share one shape: task type, agents, disruptor specs and spaces."""
    g0 = games[0]

    def shape(g: Game) -> tuple[Any, ...]:
        return (
            type(g.task),
            g.possible_agents,
            [d.spec for d in g.disruptors.values()],
            g.cost_weight,
            [g.observation_space(a) for a in g.possible_agents],
            [g.action_space(a) for a in g.possible_agents],
        )

    try:
        first = shape(g0)
        return all(shape(g) == first for g in games[1:])
    except ValueError:  # a field whose == is an array: not provably alike
        return False


def groups(games: Sequence[Game], indices: Iterable[int]) -> list[list[int]]:
    """`indices` split into runs of games about to make the same move (same movers)."""
    idx = list(indices)
    keys = [(g.move, g.next_movers, g._setup_pending) for g in (games[i] for i in idx)]
    if keys.count(keys[0]) == len(keys):  # the common case: all make the same move
        return [idx]
    by: dict[tuple[str, frozenset[str], bool], list[int]] = {}
    for i, key in zip(idx, keys, strict=True):
        by.setdefault(key, []).append(i)
    return list(by.values())


def play_all(games: Sequence[Game], actions: Mapping[str, Sequence[Any]]) -> list[Move]:
    """``[games[i].play({a: actions[a][i] for a in actions}) for i ...]``, batched.

    `games` must be alike and in one group of `groups`; ``actions[a]`` holds one action per
    game (a list, or an array ``[N, ...]``) for every agent of ``next_movers``.

    Raises:
        ActionError: as `Game.play` would, for the first game whose move fails.

    """
    g0 = games[0]
    if len(games) == 1 or g0._setup_pending:  # the setup move (t = 0) is played game by game
        return play_each(games, actions)
    g0.require(actions.keys())
    if g0.move == SENSE:
        return _sense_all(games, actions)
    return _act_all(games, actions)


def play_each(games: Sequence[Game], actions: Mapping[str, Sequence[Any]]) -> list[Move]:
    """``[games[i].play({a: actions[a][i] for a in actions}) for i ...]``, game by game.

    The unbatched form of `play_all`, for games that are not alike.
    """
    return [g.play({a: acts[i] for a, acts in actions.items()}) for i, g in enumerate(games)]


def _decode_all(
    games: Sequence[Game], attr: str, actions: Mapping[str, Sequence[Any]]
) -> tuple[dict[str, Any], list[dict[str, Any]], list[dict[str, int]]]:
    """Decode the active disruptors of list `attr` (``_sensing``, ``_act_ds``) over the games.

    Returns per agent the decoded batch, and per game what `Game` keeps (used, clipped).
    """
    g0 = games[0]
    batches: dict[str, Any] = {}
    used: list[dict[str, Any]] = [{} for _ in games]
    clipped: list[dict[str, int]] = [{} for _ in games]
    for j, d in enumerate(getattr(g0, attr)):
        a = d.agent
        if not g0._active[a]:  # the group shares its movers, so its active disruptors too
            continue
        u, counts = d.decode_rows([getattr(g, attr)[j] for g in games], actions[a])
        batches[a] = u
        for g, use, clip, row, count in zip(games, used, clipped, list(u), counts, strict=True):
            use[a] = g._last[a] = row
            clip[a] = count
    return batches, used, clipped


def _sense_all(games: Sequence[Game], actions: Mapping[str, Sequence[Any]]) -> list[Move]:
    g0 = games[0]
    batches, _, clipped = _decode_all(games, "_sensing", actions)
    shown = [g._shown for g in games]
    for j, d in enumerate(g0._sensing):
        if d.agent in batches:
            d.observation_rows([g._sensing[j] for g in games], shown, batches[d.agent])
    for g in games:
        g.move = ACT
        g.next_movers = g._act_next
    return [Move(SENSE, clip) for clip in clipped]


def _act_all(games: Sequence[Game], actions: Mapping[str, Sequence[Any]]) -> list[Move]:
    g0 = games[0]
    batches, used, clipped = _decode_all(games, "_act_ds", actions)
    acts: list[dict[str, Any]] = [{} for _ in games]
    for p, (space, shape) in g0._p_spaces.items():
        for act, row in zip(acts, protagonist_rows(p, space, shape, actions[p]), strict=True):
            act[p] = row
    if g0._env_ds:
        for g, use in zip(games, used, strict=True):
            g._disrupt_environment(use)
    for j, d in enumerate(g0._action_ds):
        peers = [g._action_ds[j] for g in games]
        if d.agent in batches:  # it moved in every game of the group
            d.action_rows(peers, acts, batches[d.agent], [g._rng for g in games])
            continue
        for g, peer, use, act in zip(games, peers, used, acts, strict=True):
            v = g._effective(peer, use)  # a held perturbation, game by game
            if v is not None:
                peer.action(act, v, g._rng)
    results = type(g0.task).step_many([g.task for g in games], acts)
    return [
        g._after_task(result, use, clip)
        for g, result, use, clip in zip(games, results, used, clipped, strict=True)
    ]
