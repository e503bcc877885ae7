"""The lean single steps (`advgame.scenarios.mujoco_lean`) return what ``env.step`` returns.

Two twin envs step the same actions, one through ``env.step`` and one through its lean form,
over whole episodes (reset on termination): every observation, reward, termination and info
value must be equal to the last bit and of the same type. The actions are large enough to make
Hopper, Walker2d and Ant fall, so the healthy checks and terminations are exercised.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import advgame
from advgame.scenarios.mujoco_lean import LEAN, lean_step
from tests._dynamics_helpers import install_recompiled_model

CASES = [
    ("HalfCheetah-v5", {}),
    ("HalfCheetah-v5", {"exclude_current_positions_from_observation": False,
                        "ctrl_cost_weight": 0.3, "forward_reward_weight": 2.0}),
    ("Hopper-v5", {}),
    ("Hopper-v5", {"terminate_when_unhealthy": False, "healthy_reward": 0.5}),
    ("Walker2d-v5", {}),
    ("Walker2d-v5", {"exclude_current_positions_from_observation": False}),
    ("Swimmer-v5", {}),
    ("Swimmer-v5", {"exclude_current_positions_from_observation": False}),
    ("Ant-v5", {}),
    ("Ant-v5", {"include_cfrc_ext_in_observation": False, "contact_cost_weight": 1e-3}),
]  # fmt: skip


def _same(a: Any, b: Any) -> bool:
    if type(a) is not type(b):
        return False
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    return bool(a == b)


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_the_lean_step_is_env_step_bit_for_bit(env_id: str, kwargs: dict) -> None:
    plain, twin = (gym.make(env_id, **kwargs).unwrapped for _ in range(2))
    lean = lean_step(twin)
    assert lean is not None
    rng = np.random.default_rng(7)
    episodes, seed = 0, 0
    plain.reset(seed=seed)
    twin.reset(seed=seed)
    for t in range(400):
        action = (rng.uniform(-1.5, 1.5, plain.action_space.shape)).astype(np.float32)
        expected, got = plain.step(action), lean(action)
        names = ("obs", "reward", "terminated", "truncated", "info")
        for name, e, g in zip(names, expected, got, strict=True):
            assert _same(e, g), f"{env_id} {kwargs} step {t}: {name} {e!r} != {g!r}"
        if expected[2] or t % 150 == 149:
            seed += 1
            episodes += 1
            plain.reset(seed=seed)
            twin.reset(seed=seed)
    assert episodes >= 2


def test_lean_steps_are_only_for_their_own_classes_and_never_draw_a_window() -> None:
    class Custom(gym.envs.mujoco.half_cheetah_v5.HalfCheetahEnv):  # type: ignore[misc]
        pass

    assert lean_step(Custom()) is None  # a subclass may change the step
    assert lean_step(gym.make("InvertedPendulum-v5").unwrapped) is None  # no lean form
    assert lean_step(gym.make("Hopper-v5", render_mode="human").unwrapped) is None
    assert set(LEAN) >= {type(gym.make("HalfCheetah-v5").unwrapped)}


def test_a_wrong_action_shape_gets_gymnasiums_own_error() -> None:
    lean = lean_step(gym.make("Hopper-v5").unwrapped)
    assert lean is not None
    with pytest.raises(ValueError, match="Action dimension mismatch"):
        lean(np.zeros(4, np.float32))


def test_a_game_plays_the_same_episode_with_and_without_the_lean_step() -> None:
    moves = []
    for lean in (True, False):
        game = advgame.make("Hopper-v5", preset="default", max_episode_steps=60)
        assert game.task._lean is not None  # type: ignore[attr-defined]
        if not lean:
            game.task._lean = None  # type: ignore[attr-defined]  # GymTask's own step
        game.reset(seed=3)
        rng = np.random.default_rng(3)
        played = []
        while game.agents:
            spaces = {a: game.action_space(a) for a in game.agents}
            acts = {a: rng.uniform(-1, 1, s.shape).astype(s.dtype) for a, s in spaces.items()}
            obs, rewards, terms, truncs, infos = game.step(acts)
            played.append((obs, rewards, terms, truncs, infos))
        moves.append(played)
    assert len(moves[0]) == len(moves[1]) > 2
    for a, b in zip(*moves, strict=True):
        assert _same(a[1], b[1]) and _same(a[2], b[2]) and _same(a[3], b[3])
        assert all(_same(a[0][k], b[0][k]) for k in a[0])
        assert all(_same(a[4][k], b[4][k]) for k in a[4])


def test_the_lean_step_follows_an_edited_timestep_and_a_swapped_model() -> None:
    plain, twin = (gym.make("HalfCheetah-v5").unwrapped for _ in range(2))
    lean = lean_step(twin)
    assert lean is not None
    plain.reset(seed=1)
    twin.reset(seed=1)
    action = np.full(6, 0.5, np.float32)
    for edit in (None, "timestep", "swap"):
        if edit == "timestep":  # edited in place: the kept options object shows it
            for env in (plain, twin):
                env.model.opt.timestep = 0.02
        elif edit == "swap":  # a recompiled model, as a dynamics disruptor installs one
            for env in (plain, twin):
                install_recompiled_model(env, timestep=0.005)
        for _ in range(5):
            expected, got = plain.step(action), lean(action)
            assert _same(expected[4], got[4]) and _same(expected[1], got[1])  # x_velocity: dt


def test_a_copied_lean_step_steps_its_own_env() -> None:
    import copy

    env = gym.make("Hopper-v5").unwrapped
    env.reset(seed=0)
    lean = lean_step(env)
    assert lean is not None
    twin_env, twin_lean = copy.deepcopy((env, lean))
    before = env.data.qpos.copy()
    twin_lean(np.ones(3, np.float32))
    assert np.array_equal(env.data.qpos, before)  # the original did not move
    assert not np.array_equal(twin_env.data.qpos, before)  # the copy did


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_control_cost_is_numpys_product_in_value_and_type(dtype: type) -> None:
    """The float32 shortcut (`_ctrl_cost` without NumPy's mixed-scalar dispatch) is exact."""
    from types import SimpleNamespace

    from advgame.scenarios.mujoco_lean import _ctrl_cost

    rng = np.random.default_rng(3)
    for weight in (0.1, 0.3, 1e-3, 1.0 / 3.0, 7.0, 0.0, 2, np.float64(0.1)):
        for _ in range(200):
            action = rng.uniform(-3, 3, 6).astype(dtype)
            expected = weight * np.sum(np.square(action))
            got = _ctrl_cost(SimpleNamespace(_ctrl_cost_weight=weight), action)
            assert type(got) is type(expected) and got == expected, (weight, action)
