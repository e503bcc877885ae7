"""`advgame.core.lockstep`: a move of N alike games at once is each game's own `play`.

Two copies of N games play the same random actions, one copy through `lockstep.play_all`
(grouped by `lockstep.groups`), the other game by game through `Game.play`: every move
(clip counts, observed and true rewards, costs, payoff, ends, info), every observation and
every disruptor's clip count must be equal, across resets that put games at different points
of their episodes, per-step schedules that split them into groups, clipped and L2-projected
adversary actions, and budgets that differ between games.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import advgame
from advgame.core import lockstep
from advgame.core.disruptor import Disruptor
from advgame.core.schedule import Schedule
from advgame.disruptors import (
    ActionDisruptor,
    ObservationDisruptor,
    RewardDisruptor,
)
from advgame.disruptors.observation import ObservationRuntime
from advgame.errors import ActionError

N = 4


def _every_kind() -> advgame.Game:
    return advgame.make("Hopper-v5", preset="full", max_episode_steps=40)


def _schedules() -> advgame.Game:
    return advgame.make(
        "Hopper-v5",
        disruptors=[
            ObservationDisruptor(eps=0.1, schedule=Schedule(probability=0.5)),
            ObservationDisruptor(
                eps=0.05,
                timing="stale",
                name="stale_adversary",
                schedule=Schedule(every=2, hold=True),
            ),
            ActionDisruptor(mode="noisy", alpha=0.3, schedule=Schedule(probability=0.5, hold=True)),
        ],
        max_episode_steps=40,
    )


def _l2_and_draws() -> advgame.Game:
    return advgame.make(
        "Hopper-v5",
        disruptors=[
            ObservationDisruptor(eps=0.2, norm="l2"),
            ActionDisruptor(mode="probabilistic", alpha=0.5),
            RewardDisruptor(eps=0.3),
        ],
        max_episode_steps=40,
    )


def _normalized() -> advgame.Game:
    return advgame.make(
        "Hopper-v5",
        disruptors=[ObservationDisruptor(eps=0.1, space="normalized"), ActionDisruptor(eps=0.2)],
        max_episode_steps=40,
    )


SETUPS: dict[str, Callable[[], advgame.Game]] = {
    "every-kind": _every_kind,
    "schedules": _schedules,
    "l2-and-draws": _l2_and_draws,
    "normalized": _normalized,
}


def _actions(game: advgame.Game, rng: np.random.Generator) -> dict[str, Any]:
    """Random actions of `game`'s next movers; adversaries' leave the box (clips)."""
    out = {}
    for a in sorted(game.next_movers):
        shape = game.action_space(a).shape
        scale = 1.0 if a in game.protagonists else 1.5
        out[a] = (scale * rng.uniform(-1, 1, shape)).astype(np.float32)
    return out


def _same(a: Any, b: Any, where: str) -> None:
    np.testing.assert_equal(a, b, err_msg=where)  # dicts, tuples and arrays, recursively


def _compare(mine: advgame.Game, ref: advgame.Game, where: str) -> None:
    for agent in mine.possible_agents:
        got, want = mine.observe(agent), ref.observe(agent)
        np.testing.assert_array_equal(got, want, err_msg=f"{where} observe {agent}", strict=True)
    for agent, d in mine.disruptors.items():
        assert d.clip_count == ref.disruptors[agent].clip_count, (where, agent)
    assert (mine.move, mine.next_movers, mine.t) == (ref.move, ref.next_movers, ref.t), where


@pytest.mark.parametrize("setup", SETUPS)
def test_play_all_makes_every_games_own_move(setup: str) -> None:
    mine = [SETUPS[setup]() for _ in range(N)]
    ref = [SETUPS[setup]() for _ in range(N)]
    if setup == "normalized":  # game 2's budget differs from the others': it perturbs alone
        for k, game in enumerate(mine + ref):
            game.set_observation_scale("protagonist", np.full(11, 2.0 if k % N == 2 else 0.5))
    rngs = [np.random.default_rng(100 + k) for k in range(N)]
    for k in range(N):
        _same(mine[k].reset(seed=k), ref[k].reset(seed=k), f"reset {k}")
    resets = groups = clipped = 0
    for step in range(300):
        actions = [_actions(game, rng) for game, rng in zip(mine, rngs, strict=True)]
        split = lockstep.groups(mine, range(N))
        groups = max(groups, len(split))
        for idx in split:
            agents = actions[idx[0]]
            moves = lockstep.play_all(
                [mine[k] for k in idx], {a: [actions[k][a] for k in idx] for a in agents}
            )
            for k, move in zip(idx, moves, strict=True):
                want = ref[k].play(actions[k])
                for field in move.__slots__:
                    _same(
                        getattr(move, field), getattr(want, field), f"step {step} game {k} {field}"
                    )
                clipped += sum(move.clipped.values())
                _compare(mine[k], ref[k], f"step {step} game {k}")
        for k in range(N):
            if not mine[k].agents or step == 7 * k + 3:  # and unaligned episodes from the start
                _same(mine[k].reset(), ref[k].reset(), f"step {step} reset {k}")
                resets += 1
    assert resets >= N and clipped > 0
    assert groups > 1  # games at different points of their episodes (or schedules) split


def test_in_box_actions_are_checked_once_for_the_whole_batch(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    calls = {"decode": 0, "observation": 0}
    decode, observation = Disruptor.decode, ObservationRuntime.observation

    def count_decode(self: Disruptor, action: Any) -> Any:
        calls["decode"] += 1
        return decode(self, action)

    def count_observation(self: ObservationRuntime, obs: Any, u: Any) -> None:
        calls["observation"] += 1
        observation(self, obs, u)

    monkeypatch.setattr(Disruptor, "decode", count_decode)
    monkeypatch.setattr(ObservationRuntime, "observation", count_observation)
    games = [
        advgame.make("Hopper-v5", disruptors=[ObservationDisruptor(eps=0.1)]) for _ in range(N)
    ]
    for k, game in enumerate(games):
        game.reset(seed=k)
    before = [game.observe("protagonist") for game in games]
    u = np.full((N, 11), 0.5, dtype=np.float32)
    lockstep.play_all(games, {"observation_adversary": u})
    assert calls == {"decode": 0, "observation": 0}  # one test, one [N, 11] sum
    for game, obs in zip(games, before, strict=True):
        np.testing.assert_allclose(game.observe("protagonist"), obs + 0.05)


@pytest.mark.parametrize(
    ("bad", "words"),
    [
        (np.array([0.1, np.nan, 0.0]), "NaN"),
        (np.zeros(4), "shape"),
        ("left", "numeric"),
    ],
    ids=["nan", "shape", "text"],
)
def test_a_bad_row_raises_what_its_own_game_would(bad: Any, words: str) -> None:
    games = [advgame.make("Hopper-v5", preset="default") for _ in range(N + 1)]
    for k, game in enumerate(games):
        game.reset(seed=k)
        game.play({"observation_adversary": np.zeros(11)})
    good = [np.zeros(3, dtype=np.float32)] * N
    actions = {"protagonist": [*good[:2], bad, *good[2:]], "action_adversary": [np.zeros(3)] * N}
    with pytest.raises(ActionError) as batch:
        lockstep.play_all(games[:N], actions)
    with pytest.raises(ActionError) as single:
        games[N].play({"protagonist": bad, "action_adversary": np.zeros(3)})
    assert str(batch.value) == str(single.value) and words in str(batch.value)


def test_games_of_other_set_ups_are_not_alike() -> None:
    same = [advgame.make("Hopper-v5", preset="default") for _ in range(2)]
    assert lockstep.alike(same)
    assert not lockstep.alike([*same, advgame.make("Hopper-v5", preset="state-gauss-0.1")])
    assert not lockstep.alike([*same, advgame.make("Walker2d-v5", preset="default")])
