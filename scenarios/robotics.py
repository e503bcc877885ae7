"""Goal-conditioned robotics scenarios: Maze, Fetch, Shadow Hand, Adroit and Franka Kitchen.

The task bases come from gymnasium-robotics 1.4.2 (`advgame.scenarios.robotics_task`).

Families and what one unit of budget means in each (observation budgets are raw units, per
component; action budgets are in the task's normalized action units, ``[-1, 1]``):

* ``maze`` (PointMaze, AntMaze): positions in metres (a PointMaze cell is 1 m, an AntMaze cell
  4 m; success within 0.45 m), velocities in m/s, AntMaze's joint angles in radians.
* ``fetch``: gripper and object positions in metres (success within 5 cm), velocities per
  control step, gripper opening in metres.
* ``hand`` (Shadow Hand; the touch-sensor variants add 92 sensor readings): joint angles in
  radians, fingertip and object positions in metres, object orientation as quaternion components.
* ``adroit``: joint angles in radians, positions in metres (a Box observation, no goal keys).
* ``kitchen``: robot joint positions/velocities and object joint states (radians, metres); the
  goals are dicts of per-task targets (``achieved_goal/kettle``, ...).

Presets of every robotics scenario:

* ``default``: per-key bounded observation attack (`OBS_EPS` of the family) and a bounded
  action attack (ε = 0.1);
* ``full``: observation, observed reward (ε = 0.1), action and a per-episode dynamics shift
  (every body's mass, gravity, geom friction, joint damping and actuator gear within ±20 %,
  except where the model lacks one: no gravity on PointMaze's plane, no actuators on Fetch's
  mocap-driven arm; see `ABSENT`);
* ``goals`` (Dict families): only the achieved and desired goals the protagonist sees, the
  family's goal budget each (the task still rewards against its true goals);
* the paper's random-mode settings (``state-gauss-0.1``, ``action-gauss-0.15``, ...; see
  `advgame.scenarios.common.gaussian_presets`). The paper lists these tasks with state, action
  and reward robustness and gives no robotics-specific numbers beyond its N(0, 0.1), N(0, 0.15)
  and U[0.2, 0.8] noise; the unbounded state noise perturbs every leaf of a Dict observation.
"""

from __future__ import annotations

from typing import Any, Literal

from advgame.core.registry import Preset
from advgame.core.schedule import Schedule
from advgame.disruptors import (
    ActionDisruptor,
    DynamicsDisruptor,
    ObservationDisruptor,
    Param,
    RewardDisruptor,
)
from advgame.scenarios.common import gaussian_presets
from advgame.scenarios.robotics_list import ENVS

__all__ = ["ACTION_EPS", "DYNAMICS", "OBS_EPS", "dynamics", "make_task", "presets"]

OBS_EPS: dict[str, Any] = {
    "maze": {"observation": 0.05, "achieved_goal": 0.1, "desired_goal": 0.1},
    "fetch": {"observation": 0.005, "achieved_goal": 0.01, "desired_goal": 0.01},
    "hand": {"observation": 0.01, "achieved_goal": 0.005, "desired_goal": 0.005},
    "adroit": 0.01,
    "kitchen": {"observation": 0.01, "achieved_goal": 0.01, "desired_goal": 0.01},
}
"""Default observation budget per family: per key for Dict observations (units: module doc)."""

ACTION_EPS = 0.1
"""Default action budget (normalized action units) for every robotics family."""

DYNAMICS: tuple[Literal["mass", "gravity", "friction", "damping", "gear"], ...] = (
    "mass",
    "gravity",
    "friction",
    "damping",
    "gear",
)
"""What the ``full`` preset shifts, within ±20 % of nominal, where the model has it."""

ABSENT: dict[str, tuple[str, ...]] = {"PointMaze": ("gravity",), "Fetch": ("gear",)}
"""Dynamics a model lacks, by id prefix: PointMaze's plane has no gravity (0 in its model) and
Fetch drives its arm by mocap (no actuators), so shifting them would be a dead adversary input."""


def dynamics(scenario_id: str) -> DynamicsDisruptor:
    """A per-episode shift of every dynamics parameter `scenario_id`'s model has, ±20 %."""
    absent = next((v for k, v in ABSENT.items() if scenario_id.startswith(k)), ())
    params = tuple(Param(k, 0.8, 1.2, relative=True) for k in DYNAMICS if k not in absent)
    return DynamicsDisruptor(params=params, schedule=Schedule.per_episode())


def make_task(env_id: str, **kwargs: Any) -> Any:
    """The gymnasium-robotics task base (imported lazily)."""
    from advgame.scenarios.robotics_task import RoboticsTask

    return RoboticsTask(env_id, **kwargs)


def _observation(family: str) -> ObservationDisruptor:
    return ObservationDisruptor(eps=OBS_EPS[family])


def presets(scenario_id: str) -> dict[str, Preset]:
    """The presets of robotics scenario `scenario_id` (see the module docstring)."""
    family = ENVS[scenario_id][0]
    obs, act = _observation(family), ActionDisruptor(eps=ACTION_EPS)
    out = {
        "default": Preset(
            (obs, act),
            description=f"bounded per-key observation ({family} budget) and action (ε = 0.1)",
        ),
        "full": Preset(
            (obs, RewardDisruptor(eps=0.1), act, dynamics(scenario_id)),
            description="observation, reward, action and a per-episode dynamics shift (±20 %)",
        ),
    }
    eps = OBS_EPS[family]
    if isinstance(eps, dict):
        goals = {k: eps[k] for k in ("achieved_goal", "desired_goal")}
        out["goals"] = Preset(
            (ObservationDisruptor(eps=goals),),
            description="the achieved and desired goals the protagonist sees, "
            f"±{goals['desired_goal']} each",
        )
    out.update(gaussian_presets())
    return out
