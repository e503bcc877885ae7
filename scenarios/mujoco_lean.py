"""Lean single steps of Gymnasium MuJoCo v5 locomotion tasks: ``env.step``'s results, less Python.

A single game spends about a fifth of a HalfCheetah-v5 step in Gymnasium's own Python around the
simulator: the action's shape check in ``do_simulation`` (the game has checked it), the ``dt``
property, ``np.sum``'s Python wrapper in the control cost, the reward terms' dict merged into the
info, the ``render_mode`` test. `lean_step` gives, for the tasks in `LEAN`, a function that
returns what ``env.step(action)`` returns, bit for bit and of the same types, with those costs
cut: the same floating-point operations in the same order (``np.add.reduce`` is the reduction
``np.sum`` calls; ``dt`` is the property's own product; a ``(qpos, qvel)`` observation is
concatenated without ``flatten``'s extra copies), the env's own ``is_healthy`` (and Ant's
``_get_obs``) and parameters read live, so dynamics disruptors and keyword arguments given to
``gymnasium.make`` act as they do on ``env.step``. `BatchedGymTask.step` uses it; any other task,
a subclass of these envs, or an env that renders to a window steps through ``env.step``.
``tests/test_mujoco_lean.py`` checks whole episodes of every task in `LEAN`, with the task's
keyword arguments varied, against ``env.step``. The batched step's formulas
(`advgame.scenarios.mujoco_formulas`) compute the same terms over ``[N, ...]`` rows; they are
not used for one env because their stacking and row extraction cost more than they save at
N = 1 (measured: a batched step of one env was slower than ``env.step``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np
from gymnasium.envs.mujoco.ant_v5 import AntEnv
from gymnasium.envs.mujoco.half_cheetah_v5 import HalfCheetahEnv
from gymnasium.envs.mujoco.hopper_v5 import HopperEnv
from gymnasium.envs.mujoco.swimmer_v5 import SwimmerEnv
from gymnasium.envs.mujoco.walker2d_v5 import Walker2dEnv

__all__ = ["LEAN", "StepOutput", "lean_dt", "lean_step"]

StepOutput = tuple[np.ndarray, Any, bool, bool, dict[str, Any]]
"""``(observation, reward, terminated, truncated, info)``, as ``env.step`` returns them."""

_add, _square = np.add.reduce, np.square
_mj_step, _post_constraint = mujoco.mj_step, mujoco.mj_rnePostConstraint


def _advance(env: Any, action: np.ndarray) -> None:
    """``MujocoEnv.do_simulation(action, frame_skip)`` once the action's shape is known right."""
    model, data = env.model, env.data
    data.ctrl[:] = action
    _mj_step(model, data, nstep=env.frame_skip)
    _post_constraint(model, data)


def lean_dt(env: Any) -> float:
    """``env.dt``: ``model.opt.timestep * frame_skip``, the same product.

    The model's options object (a view of the model's own memory: an edited timestep shows)
    is kept on the env while its model is the same object; reading ``model.opt`` makes a new
    one on every call, which cost more than the product.
    """
    model, kept = env.model, env.__dict__.get("_lean_opt")
    if kept is None or kept[0] is not model:
        kept = env._lean_opt = (model, model.opt)
    return kept[1].timestep * env.frame_skip


def _ctrl_cost(env: Any, action: np.ndarray) -> Any:
    """``env.control_cost(action)``: ``weight * np.sum(np.square(action))``.

    The action is 1-D (`lean_step` checks its shape), so the reduction along its one axis is
    ``np.sum``'s over all entries; passing no ``axis`` keyword halves the call's cost.
    """
    total, weight = _add(_square(action)), env._ctrl_cost_weight
    if _WIDENS and type(total) is np.float32 and type(weight) is float:
        # NumPy 1 widens a float32 scalar times a Python float to float64: the same double
        # product as below, without its mixed-scalar dispatch (~1.3 of ~1.6 µs, measured)
        return np.float64(weight * float(total))
    return weight * total


_WIDENS = type(0.5 * np.float32(1.0)) is np.float64
"""Whether a Python float times a float32 scalar is float64 here (NumPy 1; NumPy 2: float32)."""


def _positions_velocities(env: Any, data: Any, skip: int, clip: float | None = None) -> np.ndarray:
    """The env's ``_get_obs`` for ``(qpos, qvel)`` observations, without its extra copies.

    ``qpos`` less its first `skip` entries when the env excludes the current position, then
    ``qvel`` (clipped to ``±clip`` for Hopper and Walker2d): one new float64 array, as the
    env's ``np.concatenate`` of ``flatten()`` copies gives (``np.clip`` is ``ndarray.clip``).
    """
    position = data.qpos[skip:] if env._exclude_current_positions_from_observation else data.qpos
    velocity = data.qvel if clip is None else data.qvel.clip(-clip, clip)
    return np.concatenate((position, velocity))


def _cheetah(env: Any, action: np.ndarray) -> StepOutput:
    data = env.data
    x_before = data.qpos[0]
    _advance(env, action)
    x_after = data.qpos[0]
    x_velocity = (x_after - x_before) / lean_dt(env)
    forward = env._forward_reward_weight * x_velocity
    ctrl = _ctrl_cost(env, action)
    info = {
        "x_position": x_after,
        "x_velocity": x_velocity,
        "reward_forward": forward,
        "reward_ctrl": -ctrl,
    }
    return _positions_velocities(env, data, 1), forward - ctrl, False, False, info


def _planar_walker(env: Any, action: np.ndarray) -> StepOutput:
    """Hopper-v5 and Walker2d-v5 (their own ``is_healthy``)."""
    data = env.data
    x_before = data.qpos[0]
    _advance(env, action)
    x_after = data.qpos[0]
    x_velocity = (x_after - x_before) / lean_dt(env)
    observation = _positions_velocities(env, data, 1, clip=10.0)
    forward = env._forward_reward_weight * x_velocity
    healthy = env.is_healthy
    survive = healthy * env._healthy_reward
    ctrl = _ctrl_cost(env, action)
    info = {
        "x_position": x_after,
        "z_distance_from_origin": data.qpos[1] - env.init_qpos[1],
        "x_velocity": x_velocity,
        "reward_forward": forward,
        "reward_ctrl": -ctrl,
        "reward_survive": survive,
    }
    terminated = (not healthy) and env._terminate_when_unhealthy
    return observation, (forward + survive) - ctrl, terminated, False, info


def _swimmer(env: Any, action: np.ndarray) -> StepOutput:
    data = env.data
    xy_before = data.qpos[0:2].copy()
    _advance(env, action)
    xy_after = data.qpos[0:2].copy()
    x_velocity, y_velocity = (xy_after - xy_before) / lean_dt(env)
    forward = env._forward_reward_weight * x_velocity
    ctrl = _ctrl_cost(env, action)
    info = {
        "x_position": xy_after[0],
        "y_position": xy_after[1],
        "distance_from_origin": np.linalg.norm(xy_after, ord=2),
        "x_velocity": x_velocity,
        "y_velocity": y_velocity,
        "reward_forward": forward,
        "reward_ctrl": -ctrl,
    }
    return _positions_velocities(env, data, 2), forward - ctrl, False, False, info


def _ant(env: Any, action: np.ndarray) -> StepOutput:
    data = env.data
    body = data.body(env._main_body)
    xy_before = body.xpos[:2].copy()
    _advance(env, action)
    xy_after = data.body(env._main_body).xpos[:2].copy()
    x_velocity, y_velocity = (xy_after - xy_before) / lean_dt(env)
    observation = env._get_obs()
    forward = x_velocity * env._forward_reward_weight
    healthy = env.is_healthy
    survive = healthy * env._healthy_reward
    ctrl = _ctrl_cost(env, action)
    low, high = env._contact_force_range
    contact = env._contact_cost_weight * _add(_square(np.clip(data.cfrc_ext, low, high)), axis=None)
    info = {
        "x_position": data.qpos[0],
        "y_position": data.qpos[1],
        "distance_from_origin": np.linalg.norm(data.qpos[0:2], ord=2),
        "x_velocity": x_velocity,
        "y_velocity": y_velocity,
        "reward_forward": forward,
        "reward_ctrl": -ctrl,
        "reward_contact": -contact,
        "reward_survive": survive,
    }
    terminated = (not healthy) and env._terminate_when_unhealthy
    return observation, (forward + survive) - (ctrl + contact), terminated, False, info


LEAN: dict[type, Callable[[Any, np.ndarray], StepOutput]] = {
    HalfCheetahEnv: _cheetah,
    HopperEnv: _planar_walker,
    Walker2dEnv: _planar_walker,
    SwimmerEnv: _swimmer,
    AntEnv: _ant,
}
"""The envs (exact classes, subclasses excluded) whose step has a lean form."""


def lean_step(env: Any) -> Callable[[np.ndarray], StepOutput] | None:
    """``env.step`` in lean form for an unwrapped env of `LEAN`, else None.

    The function takes the action (a float array of the action space's shape; any other shape
    goes to ``env.step``, which raises its own error) and returns what ``env.step`` returns.
    An env that renders to a window (``render_mode="human"``) draws inside its own step: None.
    The function is a `functools.partial` of module-level functions over `env`, so it copies
    and pickles along with the env (a closure would keep stepping the original).
    """
    fn = LEAN.get(type(env))
    if fn is None or getattr(env, "render_mode", None) == "human":
        return None
    return functools.partial(_checked, fn, env, (env.model.nu,))


def _checked(
    fn: Callable[[Any, np.ndarray], StepOutput], env: Any, shape: tuple[int], action: Any
) -> StepOutput:
    """``fn(env, action)`` for an action of the right `shape`; ``env.step(action)`` otherwise."""
    if getattr(action, "shape", None) != shape:
        return env.step(action)
    return fn(env, action)
