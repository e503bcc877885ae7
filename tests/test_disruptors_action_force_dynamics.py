"""Property tests of the action, force and dynamics disruptors, through `Disruptor.decode` and
their hooks.

Each disruptor is built against a real task (Hopper-v5, LunarLander-v3) and exercised the way the
game uses it: ``u, n = d.decode(action)`` and then its one hook. Additive, probabilistic and noisy
action attacks keep the protagonist's action in its space and the change in its budget (discrete
actions included); forces stay within their bounds on the named bodies and axes; dynamics values
stay in their intervals and are restored exactly; a zero budget (or a zero-width interval at the
nominal value) is the identity; and the paper's unbounded random mode (``bounded=False``) passes
the action offset through.
"""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import advgame
from advgame.disruptors import ActionDisruptor, DynamicsDisruptor, ForceDisruptor, Param
from tests._disruptor_helpers import (
    ACT_EPS,
    ACT_N,
    DYN_PARAMS,
    FEW,
    FEWER,
    FORCE_BOUNDS,
    TORQUE_BOUND,
    P,
    adv_actions,
    box_actions,
    expected_clips,
    perturb_action,
)

# -- action -------------------------------------------------------------------------------------


@FEW
@given(eps=hnp.arrays(np.float64, (ACT_N,), elements=st.floats(0.0, 3.0)), data=st.data())
def test_action_additive_stays_in_space_and_budget(hopper, eps, data):
    space = hopper.action_space(P)
    a = data.draw(box_actions(space))
    action = data.draw(adv_actions(ACT_N))
    d = ActionDisruptor(eps=tuple(eps)).build(hopper.task)
    new, _, n = perturb_action(d, a, action)
    assert n == expected_clips(action)
    assert new.dtype == space.dtype and space.contains(new)
    # |ã - a| <= ε per dimension (plus one float32 rounding of a value of magnitude <= 1).
    assert np.all(np.abs(new.astype(np.float64) - a) <= eps + 1e-6)
    expected = np.clip(a + eps * np.clip(action, -1, 1), space.low, space.high)
    np.testing.assert_allclose(new, expected, rtol=0, atol=1e-6)


@FEW
@given(data=st.data())
def test_action_additive_module_game(hopper, data):
    space = hopper.action_space(P)
    a = data.draw(box_actions(space))
    action = data.draw(adv_actions(ACT_N))
    new, _, _ = perturb_action(hopper.disruptors["act_add"], a, action)
    assert space.contains(new)
    assert np.all(np.abs(new.astype(np.float64) - a) <= np.asarray(ACT_EPS) + 1e-6)


@FEW
@given(alpha=st.floats(0.0, 1.0), seed=st.integers(0, 2**32 - 1), data=st.data())
def test_action_probabilistic_is_the_protagonist_or_the_adversary(hopper, alpha, seed, data):
    space = hopper.action_space(P)
    a = data.draw(box_actions(space))
    action = data.draw(adv_actions(ACT_N))
    d = ActionDisruptor(mode="probabilistic", alpha=alpha).build(hopper.task)
    new, u, n = perturb_action(d, a, action, seed)
    assert n == expected_clips(action)
    assert space.contains(new)
    adv = (space.low + (u + 1.0) * 0.5 * (space.high - space.low)).astype(space.dtype)
    assert np.array_equal(new, a) or np.array_equal(new, adv)
    # The replacement happens exactly when the game's generator draws below alpha.
    replaced = np.random.default_rng(seed).random() < alpha
    assert np.array_equal(new, adv if replaced else a)


@FEW
@given(seed=st.integers(0, 2**32 - 1), data=st.data())
def test_action_probabilistic_alpha_extremes(hopper, seed, data):
    space = hopper.action_space(P)
    a = data.draw(box_actions(space))
    action = data.draw(adv_actions(ACT_N))
    never = ActionDisruptor(mode="probabilistic", alpha=0.0).build(hopper.task)
    new, _, _ = perturb_action(never, a, action, seed)
    assert np.array_equal(new, a)
    always = ActionDisruptor(mode="probabilistic", alpha=1.0).build(hopper.task)
    new, u, _ = perturb_action(always, a, action, seed)
    np.testing.assert_allclose(new, space.low + (u + 1) * 0.5 * (space.high - space.low), atol=1e-6)


@FEW
@given(alpha=st.floats(0.0, 1.0), data=st.data())
def test_action_noisy_mixes_within_alpha(hopper, alpha, data):
    space = hopper.action_space(P)
    a = data.draw(box_actions(space))
    action = data.draw(adv_actions(ACT_N))
    d = ActionDisruptor(mode="noisy", alpha=alpha).build(hopper.task)
    new, u, n = perturb_action(d, a, action)
    assert n == expected_clips(action)
    assert space.contains(new)
    span = (space.high - space.low).astype(np.float64)
    # ã - a = α (ā - a), and |ā - a| <= high - low.
    assert np.all(np.abs(new.astype(np.float64) - a) <= alpha * span + 1e-6)
    adv = space.low + (u + 1.0) * 0.5 * span
    np.testing.assert_allclose(new, (1 - alpha) * a + alpha * adv, rtol=0, atol=1e-6)
    # bit for bit: the mix is float64 (a float32 action is widened first), then clipped and cast
    mix = (1.0 - alpha) * a.astype(np.float64) + alpha * adv
    np.testing.assert_array_equal(new, np.clip(mix, space.low, space.high).astype(space.dtype))
    if alpha == 0.0:
        assert np.array_equal(new, a)


@FEW
@given(data=st.data())
def test_action_noisy_and_probabilistic_module_game(hopper, data):
    space = hopper.action_space(P)
    a = data.draw(box_actions(space))
    action = data.draw(adv_actions(ACT_N))
    new, _, _ = perturb_action(hopper.disruptors["act_noisy"], a, action)
    assert space.contains(new)
    assert np.all(np.abs(new.astype(np.float64) - a) <= 0.3 * 2.0 + 1e-6)
    new, _, _ = perturb_action(hopper.disruptors["act_prob"], a, action)
    assert space.contains(new)


@FEW
@given(
    k=st.integers(0, 3),
    alpha=st.sampled_from([0.0, 0.3, 1.0]),
    seed=st.integers(0, 2**32 - 1),
    action=adv_actions(4),
)
def test_action_discrete_lunar_lander(lunar, k, alpha, seed, action):
    space = lunar.action_space(P)
    assert isinstance(space, spaces.Discrete) and space.n == 4
    d = ActionDisruptor(mode="probabilistic", alpha=alpha).build(lunar.task)
    assert d.action_space.shape == (4,)
    new, u, n = perturb_action(d, np.int64(k), action, seed)
    assert n == expected_clips(action)
    assert space.contains(np.int64(new))
    replaced = np.random.default_rng(seed).random() < alpha
    assert int(new) == (int(np.argmax(u)) + int(space.start) if replaced else k)
    if alpha == 0.0:
        assert int(new) == k


@FEW
@given(k=st.integers(0, 3), choice=st.integers(0, 3))
def test_action_discrete_module_game_replaces_with_adversary_choice(lunar, k, choice):
    d = lunar.disruptors["act_discrete"]  # alpha = 1: always replaced
    new, _, n = perturb_action(d, np.int64(k), d.encode(choice))
    assert n == 0
    assert int(new) == choice


@pytest.mark.parametrize("mode", ["additive", "noisy"])
def test_action_modes_that_need_a_box_reject_discrete(lunar, mode):
    with pytest.raises(advgame.AdvgameError, match="probabilistic"):
        ActionDisruptor(mode=mode).build(lunar.task)


@FEW
@given(data=st.data())
def test_action_zero_budget_is_identity(hopper, data):
    space = hopper.action_space(P)
    a = data.draw(box_actions(space))
    action = data.draw(adv_actions(ACT_N))
    for spec in (
        ActionDisruptor(eps=0.0),
        ActionDisruptor(eps=(0.0, 0.0, 0.0)),
        ActionDisruptor(mode="noisy", alpha=0.0),
        ActionDisruptor(mode="probabilistic", alpha=0.0),
    ):
        new, _, _ = perturb_action(spec.build(hopper.task), a, action)
        assert np.array_equal(new, a), spec


# -- force --------------------------------------------------------------------------------------
def _force_block(sim, d):
    return sim.data.xfrc_applied[d.ids]


@FEW
@given(action=adv_actions(6))
def test_force_stays_within_bounds(hopper, action):
    sim = hopper.task.sim
    d = hopper.disruptors["force_adversary"]
    assert d.action_space.shape == (6,)  # 2 bodies x (fx, fz, ty)
    sim.data.xfrc_applied[:] = 0.0
    u, n = d.decode(action)
    assert n == expected_clips(action)
    d.environment(sim, u)
    xfrc = sim.data.xfrc_applied.copy()
    torso, foot = sim.body_id("torso"), sim.body_id("foot")
    for body, bound, part in (
        (torso, FORCE_BOUNDS[0], action[:3]),
        (foot, FORCE_BOUNDS[1], action[3:]),
    ):
        force = xfrc[body, [0, 2]]
        assert np.all(np.abs(force) <= bound)
        assert abs(xfrc[body, 4]) <= TORQUE_BOUND
        expected = np.clip(part, -1, 1) * np.array([bound, bound, TORQUE_BOUND])
        np.testing.assert_allclose(xfrc[body, [0, 2, 4]], expected, rtol=1e-12)
    # Nothing else is written: other bodies and other axes stay zero.
    mask = np.ones_like(xfrc, dtype=bool)
    mask[np.ix_([torso, foot], [0, 2, 4])] = False
    assert np.all(xfrc[mask] == 0.0)
    d.restore(sim)
    assert np.all(sim.data.xfrc_applied == 0.0)


@FEW
@given(action=adv_actions(4))
def test_force_zero_budget_is_identity(hopper, action):
    sim = hopper.task.sim
    d = ForceDisruptor(bodies=("torso", "thigh"), axes="xz", max_force=0.0).build(hopper.task)
    sim.data.xfrc_applied[:] = 0.0
    u, n = d.decode(action)
    assert n == expected_clips(action)
    d.environment(sim, u)
    assert np.all(sim.data.xfrc_applied == 0.0)


# -- dynamics -----------------------------------------------------------------------------------
def model_snapshot(sim) -> dict[str, np.ndarray]:
    m = sim.model
    return {
        "body_mass": m.body_mass.copy(),
        "body_inertia": m.body_inertia.copy(),
        "gravity": m.opt.gravity.copy(),
        "wind": m.opt.wind.copy(),
        "density": np.array(m.opt.density),
        "geom_friction": m.geom_friction.copy(),
        "dof_damping": m.dof_damping.copy(),
        "actuator_gear": m.actuator_gear.copy(),
    }


def assert_snapshot_equal(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    for key in a:
        assert np.array_equal(a[key], b[key]), key


@FEW
@given(action=adv_actions(len(DYN_PARAMS)))
def test_dynamics_values_stay_in_their_intervals(hopper, action):
    sim = hopper.task.sim
    d = hopper.disruptors["dynamics_adversary"]
    nominal = model_snapshot(sim)
    u, n = d.decode(action)
    assert n == expected_clips(action)
    values = d.values(u)
    lows = np.array([p.low for p in DYN_PARAMS])
    highs = np.array([p.high for p in DYN_PARAMS])
    assert np.all(values >= lows) and np.all(values <= highs)
    # DynamicsRuntime.values documents that a value within 1e-6·max(1, |nominal|) of the nominal
    # one *is* the nominal one (so the float32 no-op reproduces the model exactly): allow that.
    nom = d.nominal_values
    tol = np.where(np.isnan(nom), 0.0, 1e-6 * np.maximum(1.0, np.abs(np.nan_to_num(nom))))
    expected = lows + (np.clip(action, -1, 1) + 1) / 2 * (highs - lows)
    assert np.all(np.abs(values - expected) <= tol + 1e-7 * np.abs(expected)), (values, expected)
    d.environment(sim, u)
    try:
        m = sim.model
        gravity, mass, friction, damping, gear, wind = values
        torso = sim.body_id("torso")
        # Each parameter lands in the live model, inside its interval.
        assert 5.0 <= -m.opt.gravity[2] <= 15.0 and -m.opt.gravity[2] == gravity
        assert np.array_equal(m.opt.gravity[:2], nominal["gravity"][:2])
        ratio = m.body_mass[torso] / nominal["body_mass"][torso]
        assert 0.5 - 1e-12 <= ratio <= 2.0 + 1e-12
        assert m.body_mass[torso] == nominal["body_mass"][torso] * mass
        np.testing.assert_allclose(m.body_inertia[torso], nominal["body_inertia"][torso] * mass)
        others = np.arange(m.nbody) != torso
        assert np.array_equal(m.body_mass[others], nominal["body_mass"][others])
        assert np.all((m.geom_friction[:, 0] >= 0.2) & (m.geom_friction[:, 0] <= 2.0))
        assert np.all(m.geom_friction[:, 0] == friction)
        assert np.array_equal(m.geom_friction[:, 1:], nominal["geom_friction"][:, 1:])
        assert np.all((m.dof_damping >= 0.0) & (m.dof_damping <= 5.0))
        assert np.all(m.dof_damping == damping)
        gear_ratio = m.actuator_gear[:, 0] / nominal["actuator_gear"][:, 0]
        assert np.all((gear_ratio >= 0.5 - 1e-12) & (gear_ratio <= 1.5 + 1e-12))
        assert np.array_equal(m.actuator_gear[:, 0], nominal["actuator_gear"][:, 0] * gear)
        assert -3.0 <= m.opt.wind[0] <= 3.0 and m.opt.wind[0] == wind
        # the medium is air while the wind blows, nominal (vacuum) when it is still
        assert m.opt.density == (DYN_PARAMS[-1].air_density if wind != 0.0 else 0.0)
    finally:
        d.restore(sim)
    assert_snapshot_equal(model_snapshot(sim), nominal)


@pytest.mark.parametrize(
    "param",
    [
        Param("gravity", 9.81, 9.81),
        Param("mass", 1.0, 1.0, relative=True),
        Param("mass", 1.0, 1.0, names=("torso", "foot"), relative=True),
        Param("friction", 1.0, 1.0, relative=True),
        Param("friction", 2.0, 2.0, names=("foot_geom",)),
        Param("damping", 1.0, 1.0, relative=True),
        Param("damping", 1.0, 1.0, names=("thigh_joint",)),
        Param("gear", 1.0, 1.0, relative=True),
        Param("gear", 200.0, 200.0),
    ],
    ids=lambda p: f"{p.kind}-{'rel' if p.relative else 'abs'}-{'-'.join(p.names) or 'all'}",
)
@FEWER
@given(action=adv_actions(1))
def test_dynamics_zero_width_interval_at_nominal_is_identity(hopper, param, action):
    # Wind (whose air density is part of the Param) and length (a recompiled model) are covered
    # by the trajectory tests in test_dynamics_params.py.
    sim = hopper.task.sim
    nominal = model_snapshot(sim)
    d = DynamicsDisruptor(params=[param]).build(hopper.task)
    u, n = d.decode(action)
    assert n == expected_clips(action)
    d.environment(sim, u)
    try:
        assert_snapshot_equal(model_snapshot(sim), nominal)
    finally:
        d.restore(sim)


# -- the paper's unbounded random mode ----------------------------------------------------------
@FEW
@given(data=st.data())
def test_unbounded_action_offset_passes_through_decode(hopper, data):
    space = hopper.action_space(P)
    a = data.draw(box_actions(space))
    action = data.draw(hnp.arrays(np.float64, (ACT_N,), elements=st.floats(-1e30, 1e30)))
    new, u, n = perturb_action(hopper.disruptors["act_unbounded"], a, action)
    assert n == 0 and np.array_equal(u, action)
    # The simulator still only accepts actions in its space: ã = clip(a + u).
    assert space.contains(new)
    np.testing.assert_allclose(new, np.clip(a + action, space.low, space.high), rtol=0, atol=1e-6)
