"""Shared by the dynamics and force disruptor tests (tests/test_dynamics_*.py): agent names, the
Hopper-v5 observation layout, a snapshot of the model arrays a dynamics disruptor may touch, a
game with one dynamics parameter, and the plain Gymnasium trajectory to compare with."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import advgame
from advgame.core.schedule import Schedule
from advgame.disruptors import DynamicsDisruptor, Param

P = "protagonist"
DYN = "dynamics_adversary"
FORCE = "force_adversary"

# Hopper-v5 observation layout: qpos[1:] (rootz, rooty, 3 hinges), then qvel (vx, vz, ...).
VX, VZ = 5, 6


def model_snapshot(sim) -> dict[str, np.ndarray]:
    """Every model array a dynamics disruptor may touch (and a few it must not)."""
    m = sim.model
    return {
        "body_mass": m.body_mass.copy(),
        "body_inertia": m.body_inertia.copy(),
        "body_pos": m.body_pos.copy(),
        "gravity": m.opt.gravity.copy(),
        "wind": m.opt.wind.copy(),
        "density": np.array(m.opt.density),
        "viscosity": np.array(m.opt.viscosity),
        "geom_friction": m.geom_friction.copy(),
        "geom_size": m.geom_size.copy(),
        "geom_pos": m.geom_pos.copy(),
        "dof_damping": m.dof_damping.copy(),
        "actuator_gear": m.actuator_gear.copy(),
    }


def changed_keys(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> set[str]:
    return {k for k in a if a[k].shape != b[k].shape or not np.array_equal(a[k], b[k])}


def make_game(env_id: str, param: Param, schedule: Schedule | None = None):
    spec = DynamicsDisruptor(params=[param], schedule=schedule or Schedule())
    return advgame.make(env_id, disruptors=[spec])


def play_gym(env_id: str, seed: int, actions: list[np.ndarray]) -> list[np.ndarray]:
    env = gym.make(env_id, disable_env_checker=True)
    try:
        env.reset(seed=seed)
        out = []
        for a in actions:
            obs, _, term, trunc, _ = env.step(a)
            out.append(np.array(obs))
            if term or trunc:
                break
        return out
    finally:
        env.close()


def install_recompiled_model(env, timestep: float) -> None:
    """Give a Gymnasium MuJoCo `env` a model recompiled from its XML, with another `timestep`,
    and data carrying its state over: what a dynamics disruptor that recompiles installs."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(env.fullpath)
    model.opt.timestep = timestep
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = env.data.qpos, env.data.qvel
    env.model, env.data = model, data
