"""Property tests of the observation and reward/cost disruptors, through `Disruptor.decode` and
their hooks.

Each disruptor is built against a real task (Hopper-v5, LunarLander-v3) and exercised the way the
game uses it: ``u, n = d.decode(action)`` and then its one hook. Whatever finite action an
adversary sends, the perturbation stays in the budget (L∞, L2, per dimension, a subset of
dimensions, normalized units) and the observation stays in its space; a zero budget is the
identity; out-of-range values are clipped and counted; the other signal is never touched; and the
paper's unbounded random mode (``bounded=False``) passes values through unchanged.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from advgame.disruptors import ObservationDisruptor, RewardDisruptor
from tests._disruptor_helpers import (
    FEW,
    OBS_EPS,
    OBS_N,
    P,
    adv_actions,
    expected_clips,
    finite_vectors,
    perturb_obs,
    perturb_reward,
    ulp_tol,
)


# -- observation --------------------------------------------------------------------------------
@FEW
@given(
    eps=hnp.arrays(np.float64, (OBS_N,), elements=st.floats(0.0, 10.0)),
    obs=finite_vectors(OBS_N),
    action=adv_actions(OBS_N),
)
def test_observation_linf_stays_in_per_dimension_ball(hopper, eps, obs, action):
    d = ObservationDisruptor(eps=tuple(eps)).build(hopper.task)
    space = hopper.observation_space(P)
    new, n = perturb_obs(d, obs, action)
    assert n == expected_clips(action) == d.clip_count
    assert new.shape == space.shape and new.dtype == space.dtype
    assert space.contains(new)
    assert np.all(np.abs(new - obs) <= eps + ulp_tol(obs, eps))
    if n == 0:  # in range: exactly the requested offset ε ⊙ u
        np.testing.assert_allclose(new - obs, eps * action, rtol=0, atol=1e-12)


@FEW
@given(obs=finite_vectors(OBS_N), action=adv_actions(OBS_N))
def test_observation_linf_module_game(hopper, obs, action):
    d = hopper.disruptors["obs_linf"]
    new, n = perturb_obs(d, obs, action)
    assert n == expected_clips(action)
    assert np.all(np.abs(new - obs) <= OBS_EPS + ulp_tol(obs, OBS_EPS))
    # Saturated components land exactly on the boundary of the ball.
    sat = np.abs(action) >= 1.0
    np.testing.assert_allclose(np.abs(new - obs)[sat], OBS_EPS[sat], rtol=1e-12)


@FEW
@given(eps=st.floats(0.0, 10.0), obs=finite_vectors(OBS_N), action=adv_actions(OBS_N))
def test_observation_l2_stays_in_euclidean_ball(hopper, eps, obs, action):
    d = ObservationDisruptor(eps=eps, norm="l2").build(hopper.task)
    new, n = perturb_obs(d, obs, action)
    delta = new - obs
    assert n == expected_clips(action, l2=True)
    assert np.linalg.norm(delta) <= eps * (1 + 1e-12) + np.linalg.norm(ulp_tol(obs, eps))
    # δ = ε · clip(u) / max(1, ‖clip(u)‖): the direction of the (clipped) action is kept.
    c = np.clip(action, -1.0, 1.0)
    expected = eps * c / max(1.0, float(np.linalg.norm(c)))
    np.testing.assert_allclose(delta, expected, rtol=0, atol=1e-9 * (1 + eps))


@FEW
@given(obs=finite_vectors(OBS_N), action=adv_actions(OBS_N))
def test_observation_l2_module_game(hopper, obs, action):
    new, n = perturb_obs(hopper.disruptors["obs_l2"], obs, action)
    assert n == expected_clips(action, l2=True)
    assert np.linalg.norm(new - obs) <= 0.2 * (1 + 1e-12) + 1e-12 * (1 + np.abs(obs).sum())


@FEW
@given(
    eps=st.floats(0.0, 2.0),
    std=hnp.arrays(np.float64, (OBS_N,), elements=st.floats(1e-3, 100.0)),
    obs=finite_vectors(OBS_N),
    action=adv_actions(OBS_N),
)
def test_observation_normalized_budget_scales_with_std(hopper, eps, std, obs, action):
    d = ObservationDisruptor(eps=eps, space="normalized").build(hopper.task)
    d.set_scale(P, std)
    new, n = perturb_obs(d, obs, action)
    budget = eps * std
    assert n == expected_clips(action)
    assert np.all(np.abs(new - obs) <= budget + ulp_tol(obs, budget))
    if n == 0:
        np.testing.assert_allclose(new - obs, budget * action, rtol=0, atol=1e-9)
    # A value inside the normalized budget round-trips through encode/decode.
    v = budget * np.clip(action, -1.0, 1.0) * 0.5
    u, m = d.decode(d.encode(v))
    assert m == 0
    np.testing.assert_allclose(d.perturbation(u), v, rtol=1e-6, atol=1e-12)


def test_observation_normalized_set_scale_updates_the_module_game_budget(hopper, hopper_obs):
    d = hopper.disruptors["obs_norm"]
    std = np.arange(1, OBS_N + 1, dtype=np.float64)
    d.set_scale(P, std)
    new, _ = perturb_obs(d, hopper_obs, np.ones(OBS_N))
    np.testing.assert_allclose(new - hopper_obs, 0.1 * std, rtol=1e-12)
    d.set_scale(P, np.ones(OBS_N))
    new, _ = perturb_obs(d, hopper_obs, np.ones(OBS_N))
    np.testing.assert_allclose(new - hopper_obs, np.full(OBS_N, 0.1), rtol=1e-12)


@FEW
@given(
    dims=st.lists(st.integers(0, OBS_N - 1), min_size=1, max_size=OBS_N, unique=True),
    eps=st.floats(0.0, 5.0),
    norm=st.sampled_from(["linf", "l2"]),
    obs=finite_vectors(OBS_N),
    data=st.data(),
)
def test_observation_dims_subset_leaves_other_dims_alone(hopper, dims, eps, norm, obs, data):
    dims = sorted(dims)
    d = ObservationDisruptor(eps=eps, dims=dims, norm=norm).build(hopper.task)
    assert hopper.observation_space(P).shape == (OBS_N,)
    assert d.action_space.shape == (len(dims),)
    action = data.draw(adv_actions(len(dims)))
    new, n = perturb_obs(d, obs, action)
    assert n == expected_clips(action, l2=norm == "l2")
    others = np.setdiff1d(np.arange(OBS_N), dims)
    assert np.array_equal(new[others], obs[others])
    delta = new[dims] - obs[dims]
    tol = ulp_tol(obs[dims], eps)
    if norm == "linf":
        assert np.all(np.abs(delta) <= eps + tol)
    else:
        assert np.linalg.norm(delta) <= eps * (1 + 1e-12) + np.linalg.norm(tol)


@FEW
@given(obs=finite_vectors(OBS_N), action=adv_actions(3))
def test_observation_dims_module_game(hopper, obs, action):
    new, _ = perturb_obs(hopper.disruptors["obs_dims"], obs, action)
    untouched = [i for i in range(OBS_N) if i not in (0, 5, 7)]
    assert np.array_equal(new[untouched], obs[untouched])
    assert np.all(np.abs(new[[0, 5, 7]] - obs[[0, 5, 7]]) <= 0.3 + ulp_tol(obs[[0, 5, 7]], 0.3))


@FEW
@given(eps=st.floats(0.0, 20.0), data=st.data())
def test_observation_is_clipped_into_a_bounded_space(lunar, eps, data):
    space = lunar.observation_space(P)
    assert np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high))
    obs = data.draw(hnp.arrays(np.float32, space.shape, elements=st.floats(0.0, 1.0, width=32)))
    obs = np.clip(space.low + obs * (space.high - space.low), space.low, space.high)
    assert space.contains(obs)
    action = data.draw(adv_actions(space.shape[0]))
    d = ObservationDisruptor(eps=eps).build(lunar.task)
    new, n = perturb_obs(d, obs, action)
    assert n == expected_clips(action)
    assert new.dtype == space.dtype and new.shape == space.shape
    assert space.contains(new)
    # Clipping into the space only moves the value back towards the (in-space) true observation;
    # the float32 cast costs at most one float32 rounding of values of magnitude <= 10.
    assert np.all(np.abs(new.astype(np.float64) - obs) <= eps + 1e-5)


@FEW
@given(
    obs=finite_vectors(OBS_N, 1e6),
    action=adv_actions(OBS_N),
    norm=st.sampled_from(["linf", "l2"]),
    space=st.sampled_from(["raw", "normalized"]),
    vector=st.booleans(),
)
def test_observation_zero_budget_is_identity(hopper, obs, action, norm, space, vector):
    eps = (0.0,) * OBS_N if vector else 0.0
    d = ObservationDisruptor(eps=eps, norm=norm, space=space).build(hopper.task)
    if space == "normalized":
        d.set_scale(P, np.full(OBS_N, 3.0))
    new, n = perturb_obs(d, obs, action)
    assert np.array_equal(new, obs)
    assert n == expected_clips(action, l2=norm == "l2")  # still clipped and counted


# -- reward and cost ----------------------------------------------------------------------------
@FEW
@given(
    eps=st.floats(0.0, 100.0),
    signal=st.sampled_from(["reward", "cost"]),
    r=st.floats(-1e3, 1e3),
    c=st.floats(0.0, 1e3),
    action=adv_actions(1),
)
def test_reward_and_cost_change_is_bounded(hopper, eps, signal, r, c, action):
    d = RewardDisruptor(eps=eps, signal=signal).build(hopper.task)
    assert d.agent == f"{signal}_adversary"
    new_r, new_c, n = perturb_reward(d, r, c, action)
    assert n == expected_clips(action)
    changed, other, before, before_other = (
        (new_r, new_c, r, c) if signal == "reward" else (new_c, new_r, c, r)
    )
    assert other == before_other  # the other signal is never touched
    assert abs(changed - before) <= eps + ulp_tol(before, eps)
    if n == 0:
        assert changed == pytest.approx(before + eps * float(action[0]), abs=1e-9)
    if eps == 0.0:
        assert changed == before


@FEW
@given(r=st.floats(-1e3, 1e3), c=st.floats(0.0, 1e3), action=adv_actions(1))
def test_reward_and_cost_module_game(hopper, r, c, action):
    new_r, new_c, _ = perturb_reward(hopper.disruptors["reward_adversary"], r, c, action)
    assert new_c == c and abs(new_r - r) <= 0.5 + ulp_tol(r, 0.5)
    new_r, new_c, _ = perturb_reward(hopper.disruptors["cost_adversary"], r, c, action)
    assert new_r == r and abs(new_c - c) <= 0.25 + ulp_tol(c, 0.25)


# -- the paper's unbounded random mode ----------------------------------------------------------
@FEW
@given(action=hnp.arrays(np.float64, (OBS_N,), elements=st.floats(-1e30, 1e30)))
def test_unbounded_observation_passes_values_through(hopper, hopper_obs, action):
    d = hopper.disruptors["obs_unbounded"]
    assert np.all(np.isinf(d.action_space.low)) and np.all(np.isinf(d.action_space.high))
    new, n = perturb_obs(d, hopper_obs, action)
    assert n == 0 and d.clip_count == 0
    assert np.array_equal(new, hopper_obs + action)
    u, _ = d.decode(d.encode(action))  # encode is the identity, in float32 precision
    np.testing.assert_allclose(u, action, rtol=1e-6, atol=float(np.finfo(np.float32).tiny))


@FEW
@given(r=st.floats(-1e3, 1e3), action=hnp.arrays(np.float64, (1,), elements=st.floats(-1e30, 1e30)))
def test_unbounded_reward_passes_values_through(hopper, r, action):
    new_r, new_c, n = perturb_reward(hopper.disruptors["reward_unbounded"], r, 0.0, action)
    assert n == 0 and new_c == 0.0
    assert new_r == r + float(action[0])
