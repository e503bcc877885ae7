"""Dynamics schedules and the force disruptor on real MuJoCo tasks.

A persistent schedule keeps a shift across ``reset()`` (and without persist it is undone); a
per-episode shift acts only at t = 0 and holds for the episode; the force disruptor writes
``xfrc_applied``, clears it on skipped steps unless held, pushes the body and survives a length
recompile on the same step; and the appendix's sinusoidal gravity shift on Ant-v5.
"""

from __future__ import annotations

import numpy as np
import pytest

import advgame
from advgame.adversaries import SinusoidAdversary
from advgame.core.episodes import rollout
from advgame.core.schedule import Schedule
from advgame.disruptors import DynamicsDisruptor, ForceDisruptor, Param
from tests._dynamics_helpers import (
    DYN,
    FORCE,
    VX,
    P,
    changed_keys,
    make_game,
    model_snapshot,
    play_gym,
)


@pytest.mark.parametrize(
    ("param", "key"),
    [
        (Param("gravity", 9.81, 19.62), "gravity"),
        (Param("mass", 1.0, 2.0, relative=True), "body_mass"),
        (Param("friction", 0.5, 1.5, relative=True), "geom_friction"),
    ],
    ids=["gravity", "mass", "friction"],
)
@pytest.mark.parametrize(
    "schedule",
    [Schedule(persist=True), Schedule.per_episode(persist=True)],
    ids=["every-step", "per-episode"],
)
def test_persistent_schedule_keeps_the_shift_across_reset(param, key, schedule):
    game = make_game("Hopper-v5", param, schedule)
    try:
        sim = game.task.sim
        before = model_snapshot(sim)
        game.reset(seed=0)
        game.step({P: np.zeros(3, np.float32), DYN: np.ones(1, np.float32)})
        shifted = model_snapshot(sim)
        assert key in changed_keys(before, shifted)
        for seed in (1, 2):
            game.reset(seed=seed)
            assert not changed_keys(shifted, model_snapshot(sim)), "a persistent shift was undone"
    finally:
        game.close()
    # The same disruptor without persist restores (the contrast that makes the test meaningful).
    game = make_game("Hopper-v5", param, Schedule.per_episode())
    try:
        game.reset(seed=0)
        game.step({P: np.zeros(3, np.float32), DYN: np.ones(1, np.float32)})
        game.reset(seed=1)
        assert not changed_keys(before, model_snapshot(game.task.sim))
    finally:
        game.close()


def test_per_episode_schedule_acts_only_at_t0_and_holds_for_the_episode():
    game = make_game("Hopper-v5", Param("gravity", 9.81, 19.62), Schedule.per_episode())
    sim = game.task.sim
    try:
        for episode, u0 in enumerate([0.5, -0.5, 1.0]):
            game.reset(seed=episode)
            assert sim.model.opt.gravity[2] == -9.81  # nominal again at the start of each episode
            assert DYN in game.next_movers
            _, _, _, _, infos = game.step({P: np.zeros(3, np.float32), DYN: np.array([u0])})
            assert infos[DYN]["acted"] is True
            g0 = 9.81 + (u0 + 1) / 2 * (19.62 - 9.81)
            assert -sim.model.opt.gravity[2] == pytest.approx(g0, rel=1e-12)
            for t in range(1, 12):
                assert game.t == t
                assert game.next_movers == {P}, f"the adversary was asked to move at t={t}"
                # Whatever it sends now is ignored: the t=0 value holds for the episode.
                ignored = np.array([(-1.0) ** t * 0.9])
                _, _, term, trunc, infos = game.step({P: np.zeros(3, np.float32), DYN: ignored})
                assert infos[DYN] == {"acted": False, "clipped": 0}
                assert -sim.model.opt.gravity[2] == pytest.approx(g0, rel=1e-12)
                assert not (term[P] or trunc[P])
    finally:
        game.close()


def test_force_writes_xfrc_applied_and_a_skipped_step_clears_it():
    spec = ForceDisruptor(
        bodies=("torso",), axes="xz", max_force=20.0, schedule=Schedule.every_n(2)
    )
    game = advgame.make("Hopper-v5", disruptors=[spec])
    sim = game.task.sim
    try:
        game.reset(seed=0)
        torso = sim.body_id("torso")
        zero = np.zeros(3, np.float32)
        expected = np.zeros_like(sim.data.xfrc_applied)
        # t=0: active.
        _, _, _, _, infos = game.step({P: zero, FORCE: np.array([1.0, 0.5])})
        assert infos[FORCE]["acted"] is True
        expected[torso, [0, 2]] = [20.0, 10.0]
        assert np.array_equal(sim.data.xfrc_applied, expected)
        # t=1: skipped and not held -> the force is removed before the simulator steps.
        assert FORCE not in game.next_movers
        _, _, _, _, infos = game.step({P: zero, FORCE: np.array([-1.0, -1.0])})
        assert infos[FORCE]["acted"] is False
        assert np.all(sim.data.xfrc_applied == 0.0)
        # t=2: active again.
        game.step({P: zero, FORCE: np.array([-0.25, 0.0])})
        expected[torso, [0, 2]] = [-5.0, 0.0]
        assert np.array_equal(sim.data.xfrc_applied, expected)
        # Nothing leaks into the next episode.
        game.reset(seed=1)
        assert np.all(sim.data.xfrc_applied == 0.0)
    finally:
        game.close()


def test_held_force_stays_on_skipped_steps():
    spec = ForceDisruptor(
        bodies=("torso",), axes="xz", max_force=20.0, schedule=Schedule(every=2, hold=True)
    )
    game = advgame.make("Hopper-v5", disruptors=[spec])
    sim = game.task.sim
    try:
        game.reset(seed=0)
        torso = sim.body_id("torso")
        game.step({P: np.zeros(3, np.float32), FORCE: np.array([1.0, 0.5])})
        game.step({P: np.zeros(3, np.float32), FORCE: np.array([-1.0, -1.0])})  # skipped, held
        assert np.array_equal(sim.data.xfrc_applied[torso, [0, 2]], [20.0, 10.0])
    finally:
        game.close()


def test_force_pushes_the_body():
    """A +x force on the torso accelerates the hopper forward compared with no force."""
    spec = ForceDisruptor(bodies=("torso",), axes="xz", max_force=50.0)
    game = advgame.make("Hopper-v5", disruptors=[spec])
    try:
        game.reset(seed=4)
        obs, *_ = game.step({P: np.zeros(3, np.float32), FORCE: np.array([1.0, 0.0])})
        want = play_gym("Hopper-v5", 4, [np.zeros(3, np.float32)])[0]
        assert obs[P][VX] > want[VX] + 1e-3
    finally:
        game.close()


def test_force_survives_a_length_recompile_on_the_same_step():
    """A length shift recompiles the model on the step; the force of that step must still act."""
    game = advgame.make(
        "Hopper-v5",
        disruptors=[
            ForceDisruptor(bodies=("torso",), axes="xz", max_force=20.0),
            DynamicsDisruptor(params=[Param("length", 0.3, 0.5, names=("torso",))]),
        ],
    )
    sim = game.task.sim
    try:
        game.reset(seed=0)
        torso = sim.body_id("torso")
        game.step({P: np.zeros(3, np.float32), FORCE: np.array([1.0, 1.0]), DYN: np.array([1.0])})
        assert sim.model.geom_size[sim.model.body_geomadr[torso], 1] == pytest.approx(0.25)
        assert np.array_equal(sim.data.xfrc_applied[torso, [0, 2]], [20.0, 20.0])
    finally:
        game.close()


def test_sinusoid_preset_sets_gravity_per_episode_on_ant():
    game = advgame.make("Ant-v5", preset="shift-sinusoid", max_episode_steps=6)
    adversary = game.preset.adversaries[DYN]
    assert isinstance(adversary, SinusoidAdversary)
    sim = game.task.sim
    seen: dict[int, list[tuple[int, float, float, float]]] = {}
    episode = [-1]

    def protagonist(obs):
        if game.t == 0:
            episode[0] += 1
        m = sim.model
        seen.setdefault(episode[0], []).append(
            (game.t, -float(m.opt.gravity[2]), float(m.opt.wind[0]), float(m.opt.density))
        )
        return np.zeros(game.action_space(P).shape, dtype=np.float32)

    try:
        nominal_g = -float(sim.model.opt.gravity[2])
        n_episodes = 5
        results = rollout(game, {P: protagonist, DYN: adversary}, seed=0, episodes=n_episodes)
        assert sorted(seen) == list(range(n_episodes))
        for i in range(n_episodes):
            g_i = 14.715 + 4.905 * np.sin(0.5 * i)
            wind_i = 1.0 + 0.2 * np.sin(0.5 * i)
            rows = seen[i]
            t0 = [r for r in rows if r[0] == 0]
            later = [r for r in rows if r[0] > 0]
            assert t0 and later
            # t=0 is seen before the adversary's first move: the nominal model, no leakage.
            assert t0[0][1] == nominal_g and t0[0][2] == 0.0
            for _, g, wind, density in later:
                # The action space is float32: the value is exact to float32 precision.
                assert g == pytest.approx(g_i, abs=1e-5), (i, g, g_i)
                assert wind == pytest.approx(wind_i, abs=1e-6)
                assert density == 1.2
        # Every value lies inside the preset's intervals, so nothing was clipped.
        assert all(r.clipped[DYN] == 0 for r in results)
        # The shift really varies from episode to episode.
        firsts = [seen[i][1][1] for i in range(n_episodes)]
        assert len(set(np.round(firsts, 4))) == n_episodes
    finally:
        game.close()


@pytest.mark.parametrize(
    "schedule",
    [
        Schedule(),
        Schedule(every=3, start=2, stop=41),
        Schedule(once_per_episode=True, start=5),
        Schedule(probability=0.4, start=1, every=2),
        Schedule(probability=0.7, phase="eval"),
    ],
)
@pytest.mark.parametrize("phase", ["train", "eval"])
def test_schedule_rows_are_each_copys_own_schedule(schedule, phase):
    """`active_rows` of N copies = `is_active` of each copy, the same draws from each generator."""
    n = 120
    t = np.arange(n) % 60  # every step of the window's edges, each copy twice
    live = np.random.default_rng(7).random(n) < 0.8
    rows = schedule.active_rows(t, phase, [np.random.default_rng(i) for i in range(n)], live)
    singles = [np.random.default_rng(i) for i in range(n)]
    one = [bool(live[i]) and schedule.is_active(int(t[i]), phase, singles[i]) for i in range(n)]
    np.testing.assert_array_equal(rows, one)
    assert rows.dtype == np.bool_
    after = [np.random.default_rng(i) for i in range(n)]
    schedule.active_rows(t, phase, after, live)
    for a, b in zip(after, singles, strict=True):  # each generator drew as often
        assert a.random() == b.random()
