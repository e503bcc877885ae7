"""Shared by the disruptor property tests (tests/test_disruptors_*.py): the budgets of their
module games, Hypothesis strategies of adversary actions, and helpers applying one disruptor hook.

The module games themselves (`hopper`, `hopper_obs`, `lunar`) are fixtures in tests/conftest.py,
built once per test module.
"""

from __future__ import annotations

import importlib.util
from typing import Any

import numpy as np
from gymnasium import spaces
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from advgame.disruptors import Param

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


def box_actions(space: spaces.Box) -> st.SearchStrategy[np.ndarray]:
    lo, hi = float(space.low.min()), float(space.high.max())
    return hnp.arrays(space.dtype, space.shape, elements=st.floats(lo, hi, width=32))


NO_BOX2D = importlib.util.find_spec("Box2D") is None
BOX2D_REASON = "LunarLander-v3 needs the box2d extra (pip install 'advgame[box2d]')"


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


def split_schedules() -> list[Any]:
    """Disruptors whose schedules make alike copies move differently step by step.

    A probabilistic observation adversary, a stale one every 2 steps and a held one every 3
    (both holding their δ), a probabilistic noisy action adversary that holds, and a reward
    adversary in a window of steps 2-9: the array and lockstep paths' hardest bookkeeping.
    """
    from advgame.core.schedule import Schedule
    from advgame.disruptors import ActionDisruptor, ObservationDisruptor, RewardDisruptor

    return [
        ObservationDisruptor(eps=0.1, schedule=Schedule(probability=0.5)),
        ObservationDisruptor(
            eps=0.05, timing="stale", name="stale_adversary", schedule=Schedule(every=2, hold=True)
        ),
        ObservationDisruptor(
            eps=0.02, name="held_adversary", schedule=Schedule(every=3, hold=True)
        ),
        ActionDisruptor(mode="noisy", alpha=0.3, schedule=Schedule(probability=0.5, hold=True)),
        RewardDisruptor(eps=0.3, schedule=Schedule.window(2, 9)),
    ]
