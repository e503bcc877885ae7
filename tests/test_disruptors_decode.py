"""The decode contract of every disruptor kind, alone and through `Game.step`.

The bounded-adversary invariant of the design (invariant 1), for each adversary of the module
games (Hopper-v5, LunarLander-v3): extreme finite actions are clipped and counted, NaN/inf and
wrong shapes are an `ActionError` that names the agent, clip counts accumulate until reset, and
`encode` inverts `decode` inside the budget. Then the same through the game: clip counts in
``infos``, the perturbations reaching the simulator, adversaries paid on the true payoff, and
errors at ``step``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import advgame
from advgame.disruptors import (
    ActionDisruptor,
    DynamicsDisruptor,
    ForceDisruptor,
    ObservationDisruptor,
    Param,
    RewardDisruptor,
)
from advgame.errors import ActionError
from tests._disruptor_helpers import (
    ACT_EPS,
    ACT_N,
    BOX2D_REASON,
    DYN_PARAMS,
    FEW,
    FEWER,
    FORCE_BOUNDS,
    NO_BOX2D,
    OBS_EPS,
    OBS_N,
    TORQUE_BOUND,
    P,
    adv_actions,
    expected_clips,
    in_range_actions,
)

HOPPER_ADVERSARIES = [
    "obs_linf",
    "obs_l2",
    "obs_norm",
    "obs_dims",
    "obs_unbounded",
    "reward_adversary",
    "cost_adversary",
    "reward_unbounded",
    "act_add",
    "act_prob",
    "act_noisy",
    "act_unbounded",
    "force_adversary",
    "dynamics_adversary",
]
LUNAR_ADVERSARIES = ["observation_adversary", "act_discrete"]
ALL_ADVERSARIES = [("hopper", a) for a in HOPPER_ADVERSARIES] + [
    pytest.param("lunar", a, marks=pytest.mark.skipif(NO_BOX2D, reason=BOX2D_REASON))
    for a in LUNAR_ADVERSARIES
]


def test_module_games_have_the_adversaries_under_test(hopper, lunar):
    assert set(hopper.adversaries) == set(HOPPER_ADVERSARIES)
    assert set(lunar.adversaries) == set(LUNAR_ADVERSARIES)
    for name in HOPPER_ADVERSARIES:
        d = hopper.disruptors[name]
        assert hopper.action_space(name) is d.action_space
        assert d.action_space.shape == d.shape


@pytest.fixture(scope="module")
def games(hopper, request):
    lunar = None if NO_BOX2D else request.getfixturevalue("lunar")  # its cases skip without it
    return {"hopper": hopper, "lunar": lunar}


def _l2(d) -> bool:
    return getattr(d, "norm", "linf") == "l2"


@pytest.mark.parametrize(("which", "agent"), ALL_ADVERSARIES)
@FEWER
@given(signs=st.lists(st.sampled_from([-1.0, 1.0]), min_size=11, max_size=11))
def test_extreme_finite_actions_are_clipped_and_counted(games, which, agent, signs):
    d = games[which].disruptors[agent]
    size = d.shape[0]
    action = np.array(signs[:size]) * 1e30
    before = d.clip_count
    u, n = d.decode(action)
    assert np.all(np.isfinite(u))
    if not d.bounded:
        assert n == 0 and np.array_equal(u, action)
        return
    assert n == expected_clips(action, l2=_l2(d)) and n >= size
    assert d.clip_count == before + n
    assert np.all(np.abs(u) <= 1.0)
    if not _l2(d):
        assert np.array_equal(u, np.sign(action))


@pytest.mark.parametrize(("which", "agent"), ALL_ADVERSARIES)
@FEWER
@given(data=st.data(), bad=st.sampled_from([np.nan, np.inf, -np.inf]))
def test_non_finite_actions_raise_action_error_naming_the_agent(games, which, agent, data, bad):
    d = games[which].disruptors[agent]
    size = d.shape[0]
    action = data.draw(adv_actions(size))
    action[data.draw(st.integers(0, size - 1))] = bad
    with pytest.raises(ActionError) as err:
        d.decode(action)
    assert repr(agent) in str(err.value)
    with pytest.raises(ActionError, match=agent):
        d.decode(np.full(size, bad))


@pytest.mark.parametrize(("which", "agent"), ALL_ADVERSARIES)
def test_wrong_shapes_raise_action_error_naming_the_agent(games, which, agent):
    d = games[which].disruptors[agent]
    n = d.shape[0]
    bad_shapes = {(n + 1,), (n - 1,) if n > 1 else (0,), (n, 1), (1, n), (), (n, n + 1)}
    for shape in bad_shapes:
        with pytest.raises(ActionError) as err:
            d.decode(np.zeros(shape))
        assert repr(agent) in str(err.value), shape
        assert str(d.shape) in str(err.value)
    # The right shape as a plain list is accepted.
    u, clipped = d.decode([0.0] * n)
    assert u.shape == d.shape and clipped == 0


def test_clip_count_accumulates_until_reset(hopper):
    d = hopper.disruptors["act_add"]
    d.reset()
    d.decode(np.array([2.0, 0.0, -3.0]))
    d.decode(np.array([2.0, 2.0, 2.0]))
    assert d.clip_count == 5
    d.reset()
    assert d.clip_count == 0


# -- encode / decode round trips ----------------------------------------------------------------
@FEW
@given(frac=in_range_actions(OBS_N))
def test_roundtrip_observation_linf_and_dims(hopper, frac):
    d = hopper.disruptors["obs_linf"]
    v = OBS_EPS * frac
    u, n = d.decode(d.encode(v))
    assert n == 0
    np.testing.assert_allclose(d.perturbation(u), v, rtol=1e-6, atol=1e-12)
    d = hopper.disruptors["obs_dims"]
    v3 = 0.3 * frac[:3]
    u, n = d.decode(d.encode(v3))
    assert n == 0
    np.testing.assert_allclose(d.perturbation(u), v3, rtol=1e-6, atol=1e-12)


@FEW
@given(direction=in_range_actions(OBS_N), radius=st.floats(0.0, 0.999))
def test_roundtrip_observation_l2(hopper, direction, radius):
    d = hopper.disruptors["obs_l2"]
    norm = np.linalg.norm(direction)
    v = np.zeros(OBS_N) if norm == 0 else 0.2 * radius * direction / norm
    u, n = d.decode(d.encode(v))
    assert n == 0
    np.testing.assert_allclose(d.perturbation(u), v, rtol=1e-6, atol=1e-12)


@FEW
@given(frac=st.floats(-1.0, 1.0))
def test_roundtrip_reward_and_cost(hopper, frac):
    for agent, eps in (("reward_adversary", 0.5), ("cost_adversary", 0.25)):
        d = hopper.disruptors[agent]
        u, n = d.decode(d.encode([eps * frac]))
        assert n == 0
        np.testing.assert_allclose(d.perturbation(u), [eps * frac], rtol=1e-6, atol=1e-12)


@FEW
@given(frac=in_range_actions(ACT_N), target=in_range_actions(ACT_N))
def test_roundtrip_actions(hopper, frac, target):
    d = hopper.disruptors["act_add"]
    v = np.asarray(ACT_EPS) * frac
    u, n = d.decode(d.encode(v))
    assert n == 0
    np.testing.assert_allclose(d.perturbation(u), v, rtol=1e-6, atol=1e-12)
    space = hopper.action_space(P)
    for agent in ("act_prob", "act_noisy"):  # the adversary's own action ā in the action bounds
        d = hopper.disruptors[agent]
        abar = space.low + (target + 1) / 2 * (space.high - space.low)
        u, n = d.decode(d.encode(abar))
        assert n == 0
        np.testing.assert_allclose(
            space.low + (u + 1) / 2 * (space.high - space.low), abar, rtol=0, atol=1e-6
        )


@pytest.mark.parametrize("k", range(4))
def test_roundtrip_discrete_choice(lunar, k):
    d = lunar.disruptors["act_discrete"]
    u, n = d.decode(d.encode(k))
    assert n == 0
    assert int(np.argmax(u)) == k


@FEW
@given(frac=in_range_actions(6))
def test_roundtrip_force(hopper, frac):
    d = hopper.disruptors["force_adversary"]
    bounds = np.array(
        [*([FORCE_BOUNDS[0]] * 2), TORQUE_BOUND, *([FORCE_BOUNDS[1]] * 2), TORQUE_BOUND]
    )
    v = bounds * frac
    u, n = d.decode(d.encode(v))
    assert n == 0
    np.testing.assert_allclose(d.perturbation(u), v, rtol=1e-6, atol=1e-12)


@FEW
@given(frac=hnp.arrays(np.float64, (len(DYN_PARAMS),), elements=st.floats(0.0, 1.0)))
def test_roundtrip_dynamics(hopper, frac):
    d = hopper.disruptors["dynamics_adversary"]
    lows = np.array([p.low for p in DYN_PARAMS])
    highs = np.array([p.high for p in DYN_PARAMS])
    v = lows + frac * (highs - lows)
    u, n = d.decode(d.encode(v))
    assert n == 0
    values = d.values(u)
    np.testing.assert_allclose(values, v, rtol=1e-6, atol=1e-6)
    assert np.all(values >= lows) and np.all(values <= highs)


# -- through the game: clip counts in infos, errors at step ----------------------------------------
@pytest.fixture(scope="module")
def hopper_game():
    game = advgame.make(
        "Hopper-v5",
        disruptors=[
            ObservationDisruptor(eps=0.1),
            RewardDisruptor(eps=0.2),
            RewardDisruptor(eps=0.3, signal="cost"),
            ActionDisruptor(eps=0.1),
            ForceDisruptor(bodies=("torso",), axes="xz", max_force=2.0),
            DynamicsDisruptor(params=[Param("gravity", 9.81, 19.62)]),
        ],
    )
    yield game
    game.close()


def _fillers(game) -> dict[str, Any]:
    return {a: np.zeros(game.action_space(a).shape, dtype=np.float32) for a in game.possible_agents}


@FEWER
@given(magnitude=st.sampled_from([1e30, 1e6, 1.5]), data=st.data())
def test_game_step_clips_extreme_actions_and_reports_counts(hopper_game, magnitude, data):
    game = hopper_game
    sim = game.task.sim
    signs = {
        a: np.array(data.draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=n, max_size=n)))
        for a in game.adversaries
        for n in [game.action_space(a).shape[0]]
    }
    obs, _ = game.reset(seed=data.draw(st.integers(0, 1000)))
    # Sense move: the observation adversary sees s_t and shows s_t + δ_t.
    assert game.next_movers == {"observation_adversary"}
    state = np.array(game.state())
    actions = _fillers(game)
    actions["observation_adversary"] = signs["observation_adversary"] * magnitude
    obs, rewards, _, _, infos = game.step(actions)
    assert infos["observation_adversary"] == {"acted": True, "clipped": OBS_N}
    np.testing.assert_allclose(obs[P] - state, 0.1 * signs["observation_adversary"], rtol=1e-9)
    # Act move: every other adversary sends an extreme action.
    a0 = np.array([0.95, -0.95, 0.0], dtype=np.float32)
    actions = _fillers(game)
    actions[P] = a0
    for a in game.adversaries:
        actions[a] = (signs[a] * magnitude).astype(np.float64)
    obs, rewards, _, _, infos = game.step(actions)
    for a in (
        "reward_adversary",
        "cost_adversary",
        "action_adversary",
        "force_adversary",
        "dynamics_adversary",
    ):
        assert infos[a]["acted"] is True
        assert infos[a]["clipped"] == game.action_space(a).shape[0], a
    assert infos["observation_adversary"]["acted"] is False
    info = infos[P]
    assert rewards[P] - info["true_reward"] == pytest.approx(0.2 * signs["reward_adversary"][0])
    assert info["cost"] - info["true_cost"] == pytest.approx(0.3 * signs["cost_adversary"][0])
    # The protagonist's action reached the simulator as clip(a + 0.1 s) (MuJoCo's data.ctrl).
    np.testing.assert_allclose(
        sim.data.ctrl, np.clip(a0 + 0.1 * signs["action_adversary"], -1, 1), rtol=0, atol=1e-6
    )
    torso = sim.body_id("torso")
    np.testing.assert_array_equal(
        sim.data.xfrc_applied[torso, [0, 2]], 2.0 * signs["force_adversary"]
    )
    expected_g = 19.62 if signs["dynamics_adversary"][0] > 0 else 9.81
    assert -sim.model.opt.gravity[2] == pytest.approx(expected_g, rel=1e-12)
    # Adversaries are paid the negative of the true payoff, not of the perturbed reward.
    for a in game.adversaries:
        assert rewards[a] == -info["payoff"] == -info["true_reward"]


@pytest.mark.parametrize(
    "agent",
    [
        "reward_adversary",
        "cost_adversary",
        "action_adversary",
        "force_adversary",
        "dynamics_adversary",
        "observation_adversary",
    ],
)
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_game_step_rejects_non_finite_adversary_actions(hopper_game, agent, bad):
    game = hopper_game
    game.reset(seed=3)
    if agent != "observation_adversary":
        game.step(_fillers(game))  # the sense move
    assert agent in game.next_movers
    actions = _fillers(game)
    actions[agent] = np.full(game.action_space(agent).shape, bad)
    with pytest.raises(ActionError) as err:
        game.step(actions)
    assert repr(agent) in str(err.value)


@pytest.mark.parametrize(
    "agent", ["observation_adversary", "action_adversary", "dynamics_adversary"]
)
def test_game_step_rejects_wrong_shape_adversary_actions(hopper_game, agent):
    game = hopper_game
    game.reset(seed=3)
    if agent != "observation_adversary":
        game.step(_fillers(game))
    actions = _fillers(game)
    actions[agent] = np.zeros(game.action_space(agent).shape[0] + 1)
    with pytest.raises(ActionError, match=agent):
        game.step(actions)


def test_game_step_unbounded_adversary_reports_no_clips():
    game = advgame.make(
        "Hopper-v5",
        disruptors=[ObservationDisruptor(bounded=False), RewardDisruptor(bounded=False)],
    )
    try:
        game.reset(seed=0)
        state = np.array(game.state())
        actions = _fillers(game)
        big = np.full(OBS_N, 1e6)
        actions["observation_adversary"] = big
        obs, *_, infos = game.step(actions)
        assert infos["observation_adversary"] == {"acted": True, "clipped": 0}
        assert np.array_equal(obs[P], state + big)
        actions = _fillers(game)
        actions["reward_adversary"] = np.array([-1e6])
        _, rewards, *_, infos = game.step(actions)
        assert infos["reward_adversary"]["clipped"] == 0
        assert rewards[P] == infos[P]["true_reward"] - 1e6
    finally:
        game.close()
