"""The compiled stepping loop (`advgame.core.native_step`) gives the bindings' results, bit for bit.

Twin envs step the same controls through `ThreadedStepper` with the compiled loop and with the
bindings' Python loop; every simulation field a task reads must be equal to the last bit,
through contacts, resets, a model a dynamics disruptor would swap in, and two threads.
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

from advgame.core import native_step
from advgame.core.native_step import NATIVE_VAR, native_loop
from advgame.core.physics import ThreadedStepper

FIELDS = ("qpos", "qvel", "act", "qacc_warmstart", "cfrc_ext", "time")
READ = ("qpos", "qvel", "cfrc_ext")


@pytest.fixture(autouse=True)
def _threads_whatever_the_batch_costs(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ThreadedStepper, "MIN_BATCH_SECONDS", 0.0)


def _twins(env_id: str, n: int) -> tuple[list, list]:
    envs, twins = [], []
    for i in range(n):
        for group in (envs, twins):
            env = gym.make(env_id).unwrapped
            env.reset(seed=i)
            group.append(env)
    return envs, twins


def _assert_same(envs: list, twins: list) -> None:
    for a, b in zip(envs, twins, strict=True):
        for field in FIELDS:
            x, y = getattr(a.data, field), getattr(b.data, field)
            assert np.array_equal(x, y), field


needs_numba = pytest.mark.skipif(native_loop() is None, reason="numba is not installed here")


@needs_numba
@pytest.mark.parametrize(("env_id", "post"), [("Hopper-v5", False), ("Ant-v5", True)])
@pytest.mark.parametrize("threads", [1, 2])
def test_the_compiled_loop_steps_as_the_bindings_do(env_id: str, post: bool, threads: int) -> None:
    envs, twins = _twins(env_id, 5)
    native, bindings = ThreadedStepper(threads), ThreadedStepper(threads, native=False)
    rng = np.random.default_rng(0)
    nu = envs[0].model.nu
    for t in range(120):
        # large float32 actions: Hopper falls, Ant's contacts move cfrc_ext
        ctrl = rng.uniform(-2, 2, (5, nu)).astype(np.float32)
        start = np.array([e.data.qpos for e in envs])
        got = native.step(envs, ctrl, envs[0].frame_skip, post, ("qpos",), READ)
        want = bindings.step(twins, ctrl, twins[0].frame_skip, post, ("qpos",), READ)
        assert np.array_equal(got.before["qpos"], start)
        for name in READ:  # the rows read in the loop are the fields after the step
            assert np.array_equal(got.after[name], np.array([getattr(e.data, name) for e in envs]))
            assert np.array_equal(got.after[name], want.after[name])
            assert got.after[name].flags.c_contiguous and got.after[name].dtype == np.float64
        if t == 60:  # a reset in the middle: the same addresses, new state
            envs[2].reset(seed=9)
            twins[2].reset(seed=9)
    _assert_same(envs, twins)
    assert not np.array_equal(envs[0].data.qpos, envs[1].data.qpos)  # they did move
    native.close()
    bindings.close()


@needs_numba
def test_a_swapped_model_and_data_are_the_ones_stepped() -> None:
    """A dynamics disruptor may install a recompiled model: its new addresses are used."""
    envs, twins = _twins("Hopper-v5", 3)
    native, bindings = ThreadedStepper(1), ThreadedStepper(1, native=False)
    ctrl = np.full((3, 3), 0.4)
    for _ in range(5):
        native.step(envs, ctrl, 4)
        bindings.step(twins, ctrl, 4)
    for group in (envs, twins):
        env = group[1]
        model = mujoco.MjModel.from_xml_path(env.fullpath)
        model.opt.timestep = 0.004
        model.body_mass[:] *= 1.5
        data = mujoco.MjData(model)
        data.qpos[:], data.qvel[:] = env.data.qpos, env.data.qvel
        env.model, env.data = model, data
    for _ in range(30):
        native.step(envs, ctrl, 4)
        bindings.step(twins, ctrl, 4)
    _assert_same(envs, twins)
    assert envs[1].data.time == pytest.approx(30 * 4 * 0.004)  # the new data, its own clock


def test_the_variable_turns_the_compiled_loop_off(monkeypatch: pytest.MonkeyPatch) -> None:
    native_step.native_loop.cache_clear()
    monkeypatch.setenv(NATIVE_VAR, "0")
    try:
        assert native_loop() is None
        envs, twins = _twins("Hopper-v5", 2)  # and the stepper still steps, through the bindings
        ThreadedStepper(1).step(envs, np.full((2, 3), 0.2), 4)
        ThreadedStepper(1, native=False).step(twins, np.full((2, 3), 0.2), 4)
        _assert_same(envs, twins)
    finally:
        monkeypatch.delenv(NATIVE_VAR)
        native_step.native_loop.cache_clear()


@needs_numba
def test_a_field_the_loop_cannot_copy_is_read_by_the_bindings_loop() -> None:
    """``dof_island`` is an int array: the compiled loop copies doubles only, so the step falls
    back to the bindings' loop for the batch, with the same results."""
    envs, twins = _twins("Hopper-v5", 3)
    native, bindings = ThreadedStepper(1), ThreadedStepper(1, native=False)
    ctrl = np.full((3, 3), 0.4)
    got = native.step(envs, ctrl, 4, after=("qpos", "qvel", "dof_island"))
    want = bindings.step(twins, ctrl, 4, after=("qpos", "qvel", "dof_island"))
    assert got.after["dof_island"].dtype == envs[0].data.dof_island.dtype
    for name in ("qpos", "qvel"):
        assert np.array_equal(got.after[name], want.after[name])
    _assert_same(envs, twins)
