"""Property tests of every disruptor kind, through `Disruptor.decode` and its hook.

Every disruptor is built against a real task (Hopper-v5, LunarLander-v3) and exercised the way
the game uses it: ``u, n = d.decode(action)`` and then its one hook. The properties are the
bounded-adversary invariant of the design (invariant 1): whatever finite action an adversary
sends, the perturbation stays in the budget and the result stays in its space; a zero budget is
the identity; out-of-range values are clipped and counted; NaN/inf and wrong shapes are an
`ActionError` that names the agent; `encode` inverts `decode` inside the budget; and the paper's
unbounded random mode (``bounded=False``) passes values through unchanged.
"""

from __future__ import annotations

import importlib.util
from typing import Any

import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import given, settings
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

FEW = settings(max_examples=30, deadline=None)
FEWER = settings(max_examples=15, deadline=None)

P = "protagonist"
OBS_N = 11  # Hopper-v5 observation size
ACT_N = 3  # Hopper-v5 action size

# Per-dimension observation budget of the module game's L∞ adversary (all different on purpose).
OBS_EPS = np.linspace(0.01, 0.5, OBS_N)
ACT_EPS = (0.1, 0.2, 0.3)
FORCE_BOUNDS = (3.0, 1.5)  # torso, foot
TORQUE_BOUND = 0.5
DYN_PARAMS = (
    Param("gravity", 5.0, 15.0),
    Param("mass", 0.5, 2.0, names=("torso",), relative=True),
    Param("friction", 0.2, 2.0),
    Param("damping", 0.0, 5.0),
    Param("gear", 0.5, 1.5, relative=True),
    Param("wind", -3.0, 3.0),
)


# -- strategies ---------------------------------------------------------------------------------
def adv_actions(n: int) -> st.SearchStrategy[np.ndarray]:
    """Finite adversary actions: in range, slightly out of range, and absurdly large."""
    element = st.one_of(
        st.floats(-1.0, 1.0),
        st.floats(-1e30, 1e30),
        st.sampled_from([-1e30, 1e30, 1.0 + 1e-9, -1.0 - 1e-9, 1.0, -1.0, 0.0]),
    )
    return hnp.arrays(np.float64, (n,), elements=element)


def in_range_actions(n: int) -> st.SearchStrategy[np.ndarray]:
    return hnp.arrays(np.float64, (n,), elements=st.floats(-1.0, 1.0))


def finite_vectors(n: int, bound: float = 100.0) -> st.SearchStrategy[np.ndarray]:
    return hnp.arrays(np.float64, (n,), elements=st.floats(-bound, bound))


def expected_clips(a: np.ndarray, l2: bool = False) -> int:
    """What decode must report: components outside [-1, 1], plus one per L2 projection."""
    n = int(np.sum(np.abs(a) > 1.0))
    if l2 and np.linalg.norm(np.clip(a, -1.0, 1.0)) > 1.0:
        n += 1
    return n


def ulp_tol(*arrays: Any) -> np.ndarray:
    """A few units in the last place of the magnitudes involved (float64 additions round)."""
    return 4 * np.spacing(sum(np.abs(np.asarray(x, dtype=np.float64)) for x in arrays) + 1.0)


# -- games, built once per module -----------------------------------------------------------------
@pytest.fixture(scope="module")
def hopper():
    game = advgame.make(
        "Hopper-v5",
        disruptors=[
            ObservationDisruptor(eps=tuple(OBS_EPS), name="obs_linf"),
            ObservationDisruptor(eps=0.2, norm="l2", name="obs_l2"),
            ObservationDisruptor(eps=0.1, space="normalized", name="obs_norm"),
            ObservationDisruptor(eps=0.3, dims=(0, 5, 7), name="obs_dims"),
            ObservationDisruptor(bounded=False, name="obs_unbounded"),
            RewardDisruptor(eps=0.5),
            RewardDisruptor(eps=0.25, signal="cost"),
            RewardDisruptor(bounded=False, name="reward_unbounded"),
            ActionDisruptor(eps=ACT_EPS, name="act_add"),
            ActionDisruptor(mode="probabilistic", alpha=0.5, name="act_prob"),
            ActionDisruptor(mode="noisy", alpha=0.3, name="act_noisy"),
            ActionDisruptor(bounded=False, name="act_unbounded"),
            ForceDisruptor(
                bodies=("torso", "foot"),
                axes="xz",
                max_force=FORCE_BOUNDS,
                torque_axes="y",
                max_torque=TORQUE_BOUND,
            ),
            DynamicsDisruptor(params=DYN_PARAMS),
        ],
    )
    game.reset(seed=0)
    yield game
    game.close()


@pytest.fixture(scope="module")
def hopper_obs(hopper):
    obs, _ = hopper.reset(seed=0)
    return np.array(obs[P], dtype=np.float64)


NO_BOX2D = importlib.util.find_spec("Box2D") is None
BOX2D_REASON = "LunarLander-v3 needs the box2d extra (pip install 'advgame[box2d]')"


@pytest.fixture(scope="module")
def lunar():
    pytest.importorskip("Box2D", reason=BOX2D_REASON)
    game = advgame.make(
        "LunarLander-v3",
        disruptors=[
            ObservationDisruptor(eps=3.0),
            ActionDisruptor(mode="probabilistic", alpha=1.0, name="act_discrete"),
        ],
    )
    game.reset(seed=0)
    yield game
    game.close()


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


# -- helpers applying one hook ------------------------------------------------------------------
def perturb_obs(d, obs: np.ndarray, action: np.ndarray) -> tuple[np.ndarray, int]:
    u, n = d.decode(action)
    shown = {P: obs.copy()}
    d.observation(shown, u)
    return shown[P], n


def perturb_reward(d, r: float, c: float, action: np.ndarray) -> tuple[float, float, int]:
    u, n = d.decode(action)
    rewards, costs = {P: r}, {P: c}
    d.reward(rewards, costs, u)
    return rewards[P], costs[P], n


def perturb_action(d, a: Any, action: np.ndarray, seed: int = 0) -> tuple[Any, np.ndarray, int]:
    u, n = d.decode(action)
    acts = {P: a.copy() if isinstance(a, np.ndarray) else a}
    d.action(acts, u, np.random.default_rng(seed))
    return acts[P], u, n


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


# -- action -------------------------------------------------------------------------------------
def box_actions(space: spaces.Box) -> st.SearchStrategy[np.ndarray]:
    lo, hi = float(space.low.min()), float(space.high.max())
    return hnp.arrays(space.dtype, space.shape, elements=st.floats(lo, hi, width=32))


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
    # by the trajectory tests in test_dynamics.py.
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


# -- extreme, non-finite and malformed actions (every kind) -------------------------------------
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
