"""The eleven Gymnasium MuJoCo v5 tasks' observations, rewards and terminations over ``[N, ...]``.

Each formula reads the stacked `MjData` fields of the envs a batched step moved (`Stacked`) and
the task's parameters from one of those envs (``env``, a Gymnasium ``MujocoEnv``; the keyword
arguments given to ``gymnasium.make`` live there as ``_forward_reward_weight`` and so on), and
returns what that env's own ``step`` returns, row by row: the same floating-point operations in
the same order and dtypes, so every value is bit for bit the single env's
(``tests/test_mujoco_batch.py`` checks whole episodes of every task). Where a batched NumPy
operation could round differently from the single-vector one (``np.linalg.norm`` of a short
vector, which may go through BLAS, and Humanoid's ``einsum`` mass centre), the formula applies
the single-env operation row by row.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["FORMULAS", "Formula", "Outcome", "Stacked"]

Outcome = tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]
"""(observations ``[n, obs]``, rewards ``[n]``, terminated ``[n]``, info arrays) of n envs."""


class Stacked:
    """The named `MjData` fields of some envs stacked on a first axis, read on first use.

    Args:
        envs: the envs to read (objects with a live ``data``), in row order.
        known: fields already stacked (``{"qpos": [N, nq]}``), taken as they are.

    """

    def __init__(self, envs: Sequence[Any], known: dict[str, np.ndarray] | None = None) -> None:
        self._envs = envs
        if known:  # fields already read (by the stepper, env by env): not read again
            self.__dict__.update(known)

    def __getattr__(self, field: str) -> np.ndarray:
        if field.startswith("_"):
            raise AttributeError(field)
        # np.array of equal-shape rows: np.stack's values, without its Python-level checks
        # (2-4 times faster for the few-to-64 rows a batched step stacks)
        value = np.array([getattr(env.data, field) for env in self._envs])
        setattr(self, field, value)  # later reads hit the instance attribute
        return value

    def each(self, fn: Callable[[Any], Any]) -> np.ndarray:
        """``fn(env)`` for every env in order, as an array."""
        return np.array([fn(env) for env in self._envs])


def _norms(vectors: np.ndarray) -> np.ndarray:
    """``np.linalg.norm`` of each row, computed as the single env computes it.

    Each row is copied first: the norm is a BLAS dot product, and OpenBLAS's AVX-512 kernel
    adds a vector that is only 8-byte aligned (a row of a stacked ``[n, 3]`` array) in another
    order than a freshly allocated one (what the single env's subtraction gives), so the last
    bit differed on such a CPU (Pusher-v5, 27 Nov).
    """
    return np.array([np.linalg.norm(np.array(v), ord=2) for v in vectors])


def _times(weight: float, values: np.ndarray) -> np.ndarray:
    """``weight * values`` with each row promoted as the single env's scalar product is.

    A single env multiplies a NumPy scalar (``np.float32`` for float32 actions) by a Python
    number, and NumPy may promote that scalar product differently from the array product.
    The product's type depends on the two types only (NumPy 1 promotes a scalar times a Python
    number by their types; NumPy 2's Python numbers are weak), so it is found once per pair.
    """
    if len(values):
        key = (type(weight), values.dtype)
        dtype = _PRODUCT.get(key)
        if dtype is None:
            dtype = _PRODUCT[key] = (weight * values[0]).dtype
        values = values.astype(dtype, copy=False)
    return weight * values


_PRODUCT: dict[tuple[type, np.dtype], np.dtype] = {}
"""(type of the weight, dtype of the values) -> the dtype of their scalar product."""


def _ctrl_cost(weight: float, actions: np.ndarray) -> np.ndarray:
    # np.add.reduce is np.sum's own reduction, without its Python wrapper (~1 µs a step)
    return _times(weight, np.add.reduce(np.square(actions), axis=1))


def _x(g: Stacked, env: Any) -> np.ndarray:
    return g.qpos[:, 0].copy()


def _xy(g: Stacked, env: Any) -> np.ndarray:
    return g.qpos[:, 0:2].copy()


def _body_xy(g: Stacked, env: Any) -> np.ndarray:
    return g.each(lambda e: e.data.body(e._main_body).xpos[:2].copy())


def _mass_centre(g: Stacked, env: Any) -> np.ndarray:
    from gymnasium.envs.mujoco.humanoid_v5 import mass_center

    return g.each(lambda e: mass_center(e.model, e.data))


def _none(g: Stacked, env: Any) -> None:
    return None


def _cheetah(g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray) -> Outcome:
    x = g.qpos[:, 0]
    xv = (x - before) / dt
    pos = g.qpos[:, 1:] if env._exclude_current_positions_from_observation else g.qpos
    obs = np.concatenate((pos, g.qvel), axis=1)
    forward = env._forward_reward_weight * xv
    ctrl = _ctrl_cost(env._ctrl_cost_weight, act)
    info = {"x_position": x, "x_velocity": xv, "reward_forward": forward, "reward_ctrl": -ctrl}
    return obs, forward - ctrl, np.zeros(len(x), bool), info


def _planar_walker(
    g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray, hopper: bool
) -> Outcome:
    qpos, qvel = g.qpos, g.qvel
    x = qpos[:, 0]
    xv = (x - before) / dt
    pos = qpos[:, 1:] if env._exclude_current_positions_from_observation else qpos
    obs = np.concatenate((pos, np.clip(qvel, -10, 10)), axis=1)
    z, angle = qpos[:, 1], qpos[:, 2]
    (zlo, zhi), (alo, ahi) = env._healthy_z_range, env._healthy_angle_range
    healthy = (zlo < z) & (z < zhi) & (alo < angle) & (angle < ahi)
    if hopper:
        state = np.concatenate((qpos, qvel), axis=1)[:, 2:]
        slo, shi = env._healthy_state_range
        healthy &= np.all((slo < state) & (state < shi), axis=1)
    forward = env._forward_reward_weight * xv
    survive = healthy * env._healthy_reward
    ctrl = _ctrl_cost(env._ctrl_cost_weight, act)
    info = {
        "x_position": x,
        "z_distance_from_origin": qpos[:, 1] - env.init_qpos[1],
        "x_velocity": xv,
        "reward_forward": forward,
        "reward_ctrl": -ctrl,
        "reward_survive": survive,
    }
    terminated = ~healthy & bool(env._terminate_when_unhealthy)
    return obs, forward + survive - ctrl, terminated, info


def _swimmer(g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray) -> Outcome:
    xy = g.qpos[:, 0:2]
    v = (xy - before) / dt[:, None]
    pos = g.qpos[:, 2:] if env._exclude_current_positions_from_observation else g.qpos
    obs = np.concatenate((pos, g.qvel), axis=1)
    forward = env._forward_reward_weight * v[:, 0]
    ctrl = _ctrl_cost(env._ctrl_cost_weight, act)
    info = {
        "x_position": xy[:, 0],
        "y_position": xy[:, 1],
        "distance_from_origin": _norms(xy),
        "x_velocity": v[:, 0],
        "y_velocity": v[:, 1],
        "reward_forward": forward,
        "reward_ctrl": -ctrl,
    }
    return obs, forward - ctrl, np.zeros(len(xy), bool), info


def _ant(g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray) -> Outcome:
    qpos, qvel = g.qpos, g.qvel
    v = (_body_xy(g, env) - before) / dt[:, None]
    lo, hi = env._contact_force_range
    forces = np.clip(g.cfrc_ext, lo, hi)
    pos = qpos[:, 2:] if env._exclude_current_positions_from_observation else qpos
    parts = [pos, qvel]
    if env._include_cfrc_ext_in_observation:
        parts.append(forces[:, 1:].reshape(len(qpos), -1))
    obs = np.concatenate(parts, axis=1)
    zlo, zhi = env._healthy_z_range
    finite = np.all(np.isfinite(np.concatenate((qpos, qvel), axis=1)), axis=1)
    healthy = finite & (zlo <= qpos[:, 2]) & (qpos[:, 2] <= zhi)
    forward = v[:, 0] * env._forward_reward_weight
    survive = healthy * env._healthy_reward
    ctrl = _ctrl_cost(env._ctrl_cost_weight, act)
    contact = env._contact_cost_weight * np.sum(np.square(forces).reshape(len(qpos), -1), axis=1)
    info = {
        "x_position": qpos[:, 0],
        "y_position": qpos[:, 1],
        "distance_from_origin": _norms(qpos[:, 0:2]),
        "x_velocity": v[:, 0],
        "y_velocity": v[:, 1],
        "reward_forward": forward,
        "reward_ctrl": -ctrl,
        "reward_contact": -contact,
        "reward_survive": survive,
    }
    terminated = ~healthy & bool(env._terminate_when_unhealthy)
    return obs, forward + survive - (ctrl + contact), terminated, info


def _humanoid_obs(g: Stacked, env: Any) -> np.ndarray:
    n = len(g.qpos)
    pos = g.qpos[:, 2:] if env._exclude_current_positions_from_observation else g.qpos
    parts = [pos, g.qvel]
    if env._include_cinert_in_observation is True:
        parts.append(g.cinert[:, 1:].reshape(n, -1))
    if env._include_cvel_in_observation is True:
        parts.append(g.cvel[:, 1:].reshape(n, -1))
    if env._include_qfrc_actuator_in_observation is True:
        parts.append(g.qfrc_actuator[:, 6:])
    if env._include_cfrc_ext_in_observation is True:
        parts.append(g.cfrc_ext[:, 1:].reshape(n, -1))
    return np.concatenate(parts, axis=1)


def _sum_squares(values: np.ndarray) -> np.ndarray:
    return np.sum(np.square(values).reshape(len(values), -1), axis=1)


def _humanoid(g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray) -> Outcome:
    qpos = g.qpos
    v = (_mass_centre(g, env) - before) / dt[:, None]
    zlo, zhi = env._healthy_z_range
    healthy = (zlo < qpos[:, 2]) & (qpos[:, 2] < zhi)
    forward = env._forward_reward_weight * v[:, 0]
    survive = healthy * env._healthy_reward
    ctrl = env._ctrl_cost_weight * _sum_squares(g.ctrl)
    contact = np.clip(env._contact_cost_weight * _sum_squares(g.cfrc_ext), *env._contact_cost_range)
    info = {
        "x_position": qpos[:, 0],
        "y_position": qpos[:, 1],
        "tendon_length": g.ten_length,
        "tendon_velocity": g.ten_velocity,
        "distance_from_origin": _norms(qpos[:, 0:2]),
        "x_velocity": v[:, 0],
        "y_velocity": v[:, 1],
        "reward_survive": survive,
        "reward_forward": forward,
        "reward_ctrl": -ctrl,
        "reward_contact": -contact,
    }
    terminated = ~healthy & bool(env._terminate_when_unhealthy)
    return _humanoid_obs(g, env), forward + survive - (ctrl + contact), terminated, info


def _standup(g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray) -> Outcome:
    qpos = g.qpos
    up = (qpos[:, 2] - 0) / g.each(lambda e: e.model.opt.timestep)
    ctrl = env._ctrl_cost_weight * _sum_squares(g.ctrl)
    impact = np.clip(env._impact_cost_weight * _sum_squares(g.cfrc_ext), *env._impact_cost_range)
    info = {
        "x_position": qpos[:, 0],
        "y_position": qpos[:, 1],
        "z_distance_from_origin": qpos[:, 2] - env.init_qpos[2],
        "tendon_length": g.ten_length,
        "tendon_velocity": g.ten_velocity,
        "reward_linup": up,
        "reward_quadctrl": -ctrl,
        "reward_impact": -impact,
    }
    reward = up - ctrl - impact + 1
    return _humanoid_obs(g, env), reward, np.zeros(len(qpos), bool), info


def _pendulum(g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray) -> Outcome:
    obs = np.concatenate((g.qpos, g.qvel), axis=1)
    terminated = ~np.all(np.isfinite(obs), axis=1) | (np.abs(obs[:, 1]) > 0.2)
    alive = (~terminated).astype(int)
    return obs, alive, terminated, {"reward_survive": alive}


def _double_pendulum(g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray) -> Outcome:
    qpos, qvel = g.qpos, g.qvel
    site = g.site_xpos[:, 0]
    x, y = site[:, 0], site[:, 2]
    obs = np.concatenate(
        (
            qpos[:, :1],
            np.sin(qpos[:, 1:]),
            np.cos(qpos[:, 1:]),
            np.clip(qvel, -10, 10),
            np.clip(g.qfrc_constraint, -10, 10)[:, :1],
        ),
        axis=1,
    )
    terminated = y <= 1
    v1, v2 = qvel[:, 1], qvel[:, 2]
    # NumPy's scalar ``**`` and its array ``**`` may round differently: evaluate as the env does
    dist = np.array([0.01 * a**2 + (b - 2) ** 2 for a, b in zip(x, y, strict=True)])
    vel = np.array([1e-3 * a**2 + 5e-3 * b**2 for a, b in zip(v1, v2, strict=True)])
    alive = env._healthy_reward * (~terminated).astype(int)
    info = {"reward_survive": alive, "distance_penalty": -dist, "velocity_penalty": -vel}
    return obs, alive - dist - vel, terminated, info


def _body(g: Stacked, name: str) -> np.ndarray:
    return g.each(lambda e: e.data.body(name).xpos.copy())


def _reacher(g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray) -> Outcome:
    qpos = g.qpos
    vec = _body(g, "fingertip") - _body(g, "target")
    obs = np.concatenate(
        (np.cos(qpos[:, :2]), np.sin(qpos[:, :2]), qpos[:, 2:], g.qvel[:, :2], vec[:, :2]),
        axis=1,
    )
    dist = -_norms(vec) * env._reward_dist_weight
    ctrl = _times(env._reward_control_weight, -np.sum(np.square(act), axis=1))
    info = {"reward_dist": dist, "reward_ctrl": ctrl}
    return obs, dist + ctrl, np.zeros(len(qpos), bool), info


def _pusher(g: Stacked, env: Any, before: Any, act: np.ndarray, dt: np.ndarray) -> Outcome:
    tips, obj, goal = _body(g, "tips_arm"), _body(g, "object"), _body(g, "goal")
    obs = np.concatenate((g.qpos[:, :7], g.qvel[:, :7], tips, obj, goal), axis=1)
    near = -_norms(obj - tips) * env._reward_near_weight
    dist = -_norms(obj - goal) * env._reward_dist_weight
    ctrl = _times(env._reward_control_weight, -np.sum(np.square(act), axis=1))
    info = {"reward_dist": dist, "reward_ctrl": ctrl, "reward_near": near}
    return obs, dist + ctrl + near, np.zeros(len(obs), bool), info


@dataclass(frozen=True)
class Formula:
    """How one task's batched step reads the simulation.

    Attributes:
        before: what the step needs from the state before the substeps (positions for
            velocities), or nothing.
        after: observations, rewards, terminations and info arrays after the substeps.
        contact_forces: whether ``after`` reads ``cfrc_ext`` (so ``mj_rnePostConstraint``
            must run after the substeps).
        reads_before: every ``MjData`` field ``before`` reads, when it reads nothing else:
            the stepper then reads them env by env in its stepping loop
            (`advgame.core.physics.ThreadedStepper.step`) and ``before`` runs on those rows
            after the step; empty: ``before`` runs on the envs before the step.
        reads_after: ``MjData`` fields ``after`` reads that the stepping loop reads for it
            (a field not listed is still read, from the envs, after the loop).

    """

    before: Callable[[Stacked, Any], Any]
    after: Callable[[Stacked, Any, Any, np.ndarray, np.ndarray], Outcome]
    contact_forces: bool = False
    reads_before: tuple[str, ...] = ()
    reads_after: tuple[str, ...] = ()


_Q, _QV = ("qpos",), ("qpos", "qvel")

FORMULAS: dict[str, Formula] = {
    "HalfCheetah-v5": Formula(_x, _cheetah, reads_before=_Q, reads_after=_QV),
    "Hopper-v5": Formula(
        _x, functools.partial(_planar_walker, hopper=True), reads_before=_Q, reads_after=_QV
    ),
    "Walker2d-v5": Formula(
        _x, functools.partial(_planar_walker, hopper=False), reads_before=_Q, reads_after=_QV
    ),
    "Swimmer-v5": Formula(_xy, _swimmer, reads_before=_Q, reads_after=_QV),
    "Ant-v5": Formula(_body_xy, _ant, contact_forces=True, reads_after=(*_QV, "cfrc_ext")),
    "Humanoid-v5": Formula(_mass_centre, _humanoid, contact_forces=True, reads_after=_QV),
    "HumanoidStandup-v5": Formula(_none, _standup, contact_forces=True, reads_after=_QV),
    "InvertedPendulum-v5": Formula(_none, _pendulum),
    "InvertedDoublePendulum-v5": Formula(_none, _double_pendulum),
    "Reacher-v5": Formula(_none, _reacher),
    "Pusher-v5": Formula(_none, _pusher),
}
"""The batched formula of every Gymnasium MuJoCo v5 task, by id."""
