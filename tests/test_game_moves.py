"""The Game's contract, part one: move order within a step and who moves.

The sense move perturbs the true state of the same step (and a stale observation adversary lands
on the next observation); only the agents of ``next_movers`` act, as ``infos["acted"]`` says,
under every-n, per-episode and phase schedules. All on a real simulator (MuJoCo Hopper-v5); see
`advgame.core.game` for the sense/act moves these tests pin down.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import advgame
from advgame.core.schedule import Schedule
from advgame.disruptors import (
    ActionDisruptor,
    DynamicsDisruptor,
    ForceDisruptor,
    ObservationDisruptor,
    Param,
    RewardDisruptor,
)
from advgame.errors import ConfigError
from tests._game_helpers import ACT, DYN, FORCE, OBS, REW, P, ProtagonistRng, fillers, hopper


def sign_attack(s: np.ndarray) -> np.ndarray:
    """The observation adversary's deterministic choice: δ = f(s) = 0.05·sign(s), raw units."""
    return 0.05 * np.sign(s)


# -- (a) order within a step (invariant 3) ------------------------------------------------------
@pytest.mark.parametrize(("eps", "clipped_per_dim"), [(0.1, 0), (0.03, 1)])
def test_sense_move_perturbs_the_true_state_of_the_same_step(
    eps: float, clipped_per_dim: int
) -> None:
    game = hopper([ObservationDisruptor(eps=eps)], steps=40)
    encode = game.disruptors[OBS].encode
    act = ProtagonistRng(game, 1)
    obs, _ = game.reset(seed=0)
    previous: np.ndarray | None = None
    fresh_differs_from_stale = 0
    steps = 0
    while game.agents:
        # before the sense move: everyone sees the true state s_t, the simulator's own state
        s_t = obs[OBS]
        assert game.move == "sense" and game.next_movers == {OBS}
        assert np.array_equal(s_t, game.state())
        assert np.array_equal(s_t, game.task.env.unwrapped._get_obs())
        assert np.array_equal(obs[P], s_t)

        obs, rewards, terms, truncs, infos = game.step(
            fillers(game, **{OBS: encode(sign_attack(s_t))})
        )
        delta = np.clip(sign_attack(s_t), -eps, eps)
        assert np.array_equal(obs[P], s_t + delta), (obs[P] - s_t, delta)
        assert np.array_equal(obs[OBS], s_t) and np.array_equal(game.state(), s_t)
        assert infos[OBS] == {
            "acted": True,
            "clipped": clipped_per_dim * int(np.count_nonzero(s_t)),
        }
        assert not infos[P]["acted"] and all(r == 0.0 for r in rewards.values())
        assert not any(terms.values()) and not any(truncs.values())
        if previous is not None and not np.array_equal(
            obs[P], s_t + np.clip(sign_attack(previous), -eps, eps)
        ):
            fresh_differs_from_stale += 1

        assert game.move == "act" and game.next_movers == {P}
        previous = s_t
        obs, *_ = game.step(fillers(game, **{P: act()}))
        steps += 1
    assert steps >= 5
    # the test discriminates: a one-step-stale δ_{t-1} would have shown something else
    assert fresh_differs_from_stale >= 1


def test_stale_timing_lands_on_the_next_observation() -> None:
    game = hopper([ObservationDisruptor(eps=0.1, timing="stale")], steps=40)
    encode = game.disruptors[OBS].encode
    act = ProtagonistRng(game, 2)
    obs, _ = game.reset(seed=0)
    assert game.move == "act" and game.next_movers == {P, OBS}  # no sense move
    assert np.array_equal(obs[P], obs[OBS])  # nothing chosen yet at t = 0
    differs_from_fresh = 0
    steps = 0
    while True:
        s_t = obs[OBS]
        obs, rewards, _, _, infos = game.step({P: act(), OBS: encode(sign_attack(s_t))})
        steps += 1
        assert infos[OBS]["acted"] and infos[P]["acted"]
        assert rewards[OBS] == -infos[P]["payoff"]
        if not game.agents:
            break
        s_next = obs[OBS]
        assert np.array_equal(s_next, game.state())
        assert np.array_equal(obs[P], s_next + sign_attack(s_t)), (obs[P] - s_next, s_t)
        if not np.array_equal(obs[P], s_next + sign_attack(s_next)):
            differs_from_fresh += 1
    assert steps >= 5
    assert differs_from_fresh >= 1


# -- (b) who moves: next_movers and infos["acted"] --------------------------------------------
ALL_KINDS = (
    ObservationDisruptor(eps=0.1),
    ObservationDisruptor(eps=0.1, timing="stale", name="stale_adversary"),
    ActionDisruptor(eps=0.1),
    RewardDisruptor(eps=0.1),
    DynamicsDisruptor(params=[Param("mass", 0.8, 1.2, relative=True)]),
    ForceDisruptor(bodies=("foot",), axes="xz", max_force=3.0),
)


def _play(
    game: advgame.Game,
    seed: int,
    adversary_action: Callable[[str, int], Any],
    protagonist: Callable[[], Any],
) -> list[tuple[int, str, frozenset, dict]]:
    """Play one episode; return (t, move, next_movers, infos) of every move."""
    game.reset(seed=seed)
    for i, agent in enumerate(game.adversaries):  # reproducible .sample() for adversaries
        game.action_space(agent).seed(seed + i)
    log = []
    while game.agents:
        t, move, movers = game.t, game.move, game.next_movers
        actions = {a: adversary_action(a, t) for a in game.adversaries}
        actions[P] = protagonist()
        *_, infos = game.step(actions)
        log.append((t, move, movers, infos))
    return log


def test_sense_move_uses_only_observation_adversaries_and_act_move_the_rest() -> None:
    game = hopper(ALL_KINDS, steps=12)
    rng = ProtagonistRng(game, 3)
    log = _play(game, 0, lambda a, t: game.action_space(a).sample(), rng)
    act_movers = {P, "stale_adversary", ACT, REW, DYN, FORCE}
    assert [m for _, m, _, _ in log] == ["sense", "act"] * 12
    for t, move, movers, infos in log:
        expected = {OBS} if move == "sense" else act_movers
        assert movers == expected, (t, move, movers)
        assert {a for a, i in infos.items() if i["acted"]} == expected, (t, move, infos)


def test_every_n_and_per_episode_schedules_say_who_moves() -> None:
    disruptors = [
        ObservationDisruptor(eps=0.1, schedule=Schedule.every_n(3)),
        ActionDisruptor(eps=0.1, schedule=Schedule.every_n(3)),
        DynamicsDisruptor(params=[Param("gravity", 8.0, 12.0)], schedule=Schedule.per_episode()),
    ]
    game = hopper(disruptors, steps=10)
    log = _play(game, 0, lambda a, t: game.action_space(a).sample(), ProtagonistRng(game, 4))
    expected = []
    for t in range(10):
        if t % 3 == 0:
            expected.append((t, "sense", frozenset({OBS})))
        act = {P} | ({ACT} if t % 3 == 0 else set()) | ({DYN} if t == 0 else set())
        expected.append((t, "act", frozenset(act)))
    assert [(t, m, movers) for t, m, movers, _ in log] == expected
    for _, _, movers, infos in log:
        assert {a for a, i in infos.items() if i["acted"]} == movers


def test_action_of_an_inactive_adversary_does_not_count() -> None:
    """Off-schedule garbage from an every-3 action adversary changes nothing; on-schedule counts."""

    def run(off_schedule: float, on_schedule: float) -> list[np.ndarray]:
        game = hopper([ActionDisruptor(eps=0.5, schedule=Schedule.every_n(3))], steps=15)
        act = ProtagonistRng(game, 5)
        obs, _ = game.reset(seed=0)
        seen = [obs[P]]
        while game.agents:
            u = on_schedule if game.t % 3 == 0 else off_schedule
            obs, _, _, _, infos = game.step({P: act(), ACT: np.full(3, u, dtype=np.float32)})
            assert infos[ACT]["clipped"] == (3 if infos[ACT]["acted"] and abs(u) > 1 else 0)
            seen.append(obs[P])
        return seen

    base = run(off_schedule=1.0, on_schedule=1.0)
    off = run(off_schedule=-7.0, on_schedule=1.0)
    on = run(off_schedule=1.0, on_schedule=-1.0)
    assert len(base) == len(off)
    assert all(np.array_equal(a, b) for a, b in zip(base, off, strict=True))
    assert not all(np.array_equal(a, b) for a, b in zip(base, on, strict=False))


def test_phase_schedules_and_reset_option_switch() -> None:
    disruptors = [
        ObservationDisruptor(eps=0.1, schedule=Schedule(phase="eval")),
        ActionDisruptor(eps=0.1, schedule=Schedule(phase="train")),
    ]
    game = hopper(disruptors, steps=6)
    assert game.phase == "train"
    ones = lambda a, t: np.ones(game.action_space(a).shape, dtype=np.float32)  # noqa: E731

    obs, _ = game.reset(seed=0)
    assert game.move == "act" and game.next_movers == {P, ACT}
    log = _play(game, 0, ones, ProtagonistRng(game, 6))
    assert all(move == "act" and movers == {P, ACT} for _, move, movers, _ in log)
    assert all(not infos[OBS]["acted"] and infos[ACT]["acted"] for *_, infos in log)

    obs, _ = game.reset(seed=0, options={"phase": "eval"})
    assert game.phase == "eval"
    assert game.move == "sense" and game.next_movers == {OBS}
    obs, *_ = game.step(fillers(game, **{OBS: np.ones(11, dtype=np.float32)}))
    assert np.array_equal(obs[P], game.state() + 0.1)
    assert game.next_movers == {P}
    game.reset(seed=0)  # no options: the phase stays
    assert game.phase == "eval" and game.next_movers == {OBS}
    log = _play(game, 0, ones, ProtagonistRng(game, 6))
    assert [(m, movers) for _, m, movers, _ in log] == [("sense", {OBS}), ("act", {P})] * (
        len(log) // 2
    )

    game.reset(seed=0, options={"phase": "train"})
    assert game.phase == "train" and game.next_movers == {P, ACT}
    with pytest.raises(ConfigError, match="'test'"):
        game.reset(options={"phase": "test"})


def test_observation_adversary_inactive_in_train_phase_leaves_the_state_alone() -> None:
    game = hopper([ObservationDisruptor(eps=0.1, schedule=Schedule(phase="eval"))], steps=10)
    act = ProtagonistRng(game, 7)
    obs, _ = game.reset(seed=0)
    while game.agents:
        assert np.array_equal(obs[P], game.state())
        obs, *_ = game.step({P: act(), OBS: np.ones(11, dtype=np.float32)})
