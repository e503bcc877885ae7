"""MuJoCo's profiling timers are off where games step, and the physics does not notice.

`advgame.core.mujoco_timers.quiet_timers` unsets MuJoCo's global ``mjcb_time`` (the bindings
set it whenever they make an ``MjData``): the games call it at reset, after a recompile and
before each batched step. These tests check that a simulator stepped with the timers on and one
stepped with them off end in the same state bit for bit, that a game's reset, a recompile and a
batched step leave them off, and that ``ADVGAME_MUJOCO_TIMERS=1`` keeps them.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import advgame
from advgame.core.array_game import ArrayGame
from advgame.core.mujoco_timers import TIMERS_VAR, quiet_timers, timer_slot
from advgame.disruptors import DynamicsDisruptor
from advgame.disruptors.dynamics import Param

FIELDS = ("qpos", "qvel", "qacc", "act", "cfrc_ext", "contact", "efc_force", "time")


def _on() -> None:
    """Make an MjData with the callback unset: the bindings install their timer again."""
    import mujoco

    quiet_timers()
    mujoco.MjData(mujoco.MjModel.from_xml_string("<mujoco/>"))
    slot = timer_slot()
    if slot is None or not slot.value:
        pytest.skip(f"MuJoCo {mujoco.__version__}'s bindings set no timer: nothing to switch off")


def _stepped(timers: bool, steps: int = 300) -> dict[str, np.ndarray]:
    env = gym.make("Ant-v5").unwrapped  # contacts: the constraint solver's timed stages run
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    slot = timer_slot()
    assert slot is not None
    for _ in range(steps):
        if timers:
            _on()
            assert slot.value
        else:
            quiet_timers()
            assert not slot.value
        env.step(rng.uniform(-1, 1, env.action_space.shape))
    data = env.data
    out = {f: np.array(getattr(data, f)) for f in FIELDS if f != "contact"}
    out["contact"] = np.array(data.contact.dist)
    out["timed"] = np.array(data.timer[0].duration)
    env.close()
    return out


def test_physics_is_the_same_with_and_without_timers() -> None:
    with_timers, without = _stepped(True), _stepped(False)
    assert with_timers["timed"] > 0 and without["timed"] == 0  # the clocks ran in one only
    for field in FIELDS:
        np.testing.assert_array_equal(with_timers[field], without[field], err_msg=field)


def test_games_turn_them_off() -> None:
    slot = timer_slot()
    assert slot is not None
    game = advgame.make("Hopper-v5", preset="default")
    _on()
    game.reset(seed=0)
    assert not slot.value
    spec = [DynamicsDisruptor(params=[Param("length", 0.3, 0.5, names=("torso",))])]
    game = advgame.make("Hopper-v5", disruptors=spec)
    game.reset(seed=0)
    sim = game.task.sim
    epoch = sim.epoch
    _on()
    game.play({a: game.action_space(a).sample() for a in game.next_movers})
    assert sim.epoch > epoch  # the length shift recompiled the model: a new MjData
    assert not slot.value
    array = ArrayGame([advgame.make("HalfCheetah-v5", preset="default") for _ in range(2)])
    array.reset(seed=0)
    _on()
    array.sense({"observation_adversary": np.zeros((2, 17))})
    array.act({"protagonist": np.zeros((2, 6)), "action_adversary": np.zeros((2, 6))})
    assert not slot.value


def test_the_variable_keeps_them(monkeypatch: pytest.MonkeyPatch) -> None:
    slot = timer_slot()
    assert slot is not None
    monkeypatch.setenv(TIMERS_VAR, "1")
    _on()
    advgame.make("Hopper-v5", preset="default").reset(seed=0)
    assert slot.value
    monkeypatch.delenv(TIMERS_VAR)
    quiet_timers()
    assert not slot.value
