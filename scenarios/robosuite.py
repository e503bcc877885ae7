"""robosuite scenarios (family ``"robosuite"``): the paper's twelve tasks and its two causal ones.

Presets of every robosuite scenario:

* ``default``: bounded observation (ε = 0.05, raw units) and action (ε = 0.1) adversaries;
* ``full``: observation, observed-reward, action and a per-episode dynamics shift (every body's
  mass, geom friction and joint damping within ±20 % of nominal).

Lift, Stack and Door add ``object-obs`` (an observation attack on the ``object-state`` key only,
ε = 0.05; any scenario takes ``ObservationDisruptor(keys=["object-state"])``) and ``table`` (table offset and height per episode: ±5 cm in x and y,
±3 cm in height, objects moving with the table); Door adds ``door-shift`` (one adversary
dimension moves the door up to 10 cm away and raises the handle up to 5 cm, together); Lift adds
``lift-shift`` (one dimension moves the cube up to 8 cm along y and turns it blue (u > 0) or
green (u < 0)). These two were called ``door-causal`` and ``lift-causal`` before the paper's
causal tasks arrived: those are the scenarios ``RS-LiftCausal`` and ``RS-DoorCausal``, whose
presets are in `advgame.scenarios.robosuite_causal`. MultiRobustDoor's ``default`` is the
adversarial arm (robot 1, its controller's full range), and so is its ``rarl`` (what
``--method rarl`` trains: the arm at half its range, evaluated at its full range); its ``full``
adds observation and action adversaries.
"""

from __future__ import annotations

from typing import Any

from advgame.adversaries import GaussianAdversary
from advgame.core.registry import Preset
from advgame.core.schedule import Schedule
from advgame.disruptors import (
    ActionDisruptor,
    ArmDisruptor,
    DynamicsDisruptor,
    ObservationDisruptor,
    Param,
    RewardDisruptor,
    Shift,
    WorkspaceDisruptor,
)
from advgame.scenarios.robosuite_causal import CAUSAL_TASKS, causal_presets

__all__ = ["ENVS", "door_shift", "lift_shift", "make_task", "presets", "table_shift"]

ENVS: dict[str, dict[str, Any]] = {
    "Lift": {"robots": "Panda"},
    "Stack": {"robots": "Panda"},
    "NutAssembly": {"robots": "Panda"},
    "PickPlace": {"robots": "Panda"},
    "Door": {"robots": "Panda"},
    "Wipe": {"robots": "Panda"},
    "ToolHang": {"robots": "Panda"},
    "TwoArmLift": {"robots": ["Panda", "Panda"]},
    "TwoArmPegInHole": {"robots": ["Panda", "Panda"]},
    "TwoArmHandover": {"robots": ["Panda", "Panda"]},
    "TwoArmTransport": {"robots": ["Panda", "Panda"]},
    "MultiRobustDoor": {"robots": ["Panda", "Panda"], "external_robots": (1,)},
    "LiftCausal": {"robots": "Panda", "max_episode_steps": 300},
    "DoorCausal": {"robots": "Panda", "max_episode_steps": 300},
}
"""Task-base keyword arguments per robosuite environment (scenario id ``"RS-<env>"``).

The causal tasks keep the Robust Gymnasium paper's horizon, 300 steps (its RSC table); the
others truncate at the task base's 200. A ``max_episode_steps`` given to `advgame.make` wins."""

TABLE_OBJECTS = {
    "Lift": ("cube_main",),
    "Stack": ("cubeA_main", "cubeB_main"),
    "Door": ("Door_main",),
}
"""Object root bodies that sit on the table and move with it."""


def make_task(env_name: str, **kwargs: Any) -> Any:
    """The robosuite task base (imported lazily: robosuite is slow to import)."""
    from advgame.scenarios.robosuite_task import RobosuiteTask

    return RobosuiteTask(env_name, **{**ENVS[env_name], **kwargs})


def table_shift(env_name: str, xy: float = 0.05, z: float = 0.03) -> WorkspaceDisruptor:
    """Table offset (x, y) and height per episode; the objects on it move with it."""
    bodies = ("table", *TABLE_OBJECTS[env_name])
    return WorkspaceDisruptor(
        shifts=(
            Shift("table_x", bodies=bodies, offset=(xy, 0.0, 0.0)),
            Shift("table_y", bodies=bodies, offset=(0.0, xy, 0.0)),
            Shift("table_z", bodies=bodies, offset=(0.0, 0.0, z)),
        )
    )


def door_shift(distance: float = 0.10, height: float = 0.05) -> WorkspaceDisruptor:
    """Door distance and handle height varied together by one adversary dimension."""
    return WorkspaceDisruptor(
        shifts=(
            Shift(
                "door",
                body_offsets=(
                    ("Door_main", (distance, 0.0, 0.0)),
                    ("Door_latch", (0.0, 0.0, height)),
                ),
            ),
        )
    )


def lift_shift(distance: float = 0.08) -> WorkspaceDisruptor:
    """Cube position and colour (not observed in state) varied together by one dimension."""
    return WorkspaceDisruptor(
        shifts=(
            Shift(
                "cube",
                bodies=("cube_main",),
                offset=(0.0, distance, 0.0),
                geoms=("cube_g0_vis",),
                rgba_high=(0.0, 0.2, 1.0, 1.0),
                rgba_low=(0.0, 0.8, 0.1, 1.0),
            ),
        )
    )


def _dynamics() -> DynamicsDisruptor:
    params = tuple(Param(k, 0.8, 1.2, relative=True) for k in ("mass", "friction", "damping"))
    return DynamicsDisruptor(params=params, schedule=Schedule.per_episode())


def presets(scenario_id: str) -> dict[str, Preset]:
    """The presets of robosuite scenario `scenario_id` (see the module docstring)."""
    env = scenario_id.removeprefix("RS-")
    base = (ObservationDisruptor(eps=0.05), ActionDisruptor(eps=0.1))
    full = (*base[:1], RewardDisruptor(eps=0.1), base[1], _dynamics())
    if scenario_id in CAUSAL_TASKS:
        return causal_presets(scenario_id, full)
    if env == "MultiRobustDoor":
        arm = ArmDisruptor(robot=1)
        return {
            "default": Preset((arm,), description="an adversarial second arm (robot 1)"),
            "rarl": Preset((arm,), description="the adversarial arm (for --method rarl)"),
            "full": Preset((arm, *full), description="adversarial arm and every other kind"),
        }
    out = {
        "default": Preset(base, description="bounded observation and action adversaries"),
        "full": Preset(full, description="observation, reward, action and dynamics"),
    }
    if env in TABLE_OBJECTS:
        out["object-obs"] = _object_obs()
        out["table"] = Preset(
            (table_shift(env),), description="table offset and height per episode"
        )
    if env == "Door":
        out["door-shift"] = Preset(
            (door_shift(),), description="door distance + handle height, together"
        )
    if env == "Lift":
        out["lift-shift"] = Preset((lift_shift(),), description="cube position + colour, together")
    return out


def _object_obs() -> Preset:
    return Preset(
        (ObservationDisruptor(eps=0.05, keys=("object-state",)),),
        {"observation_adversary": GaussianAdversary(std=0.02)},
        "observation attack on the object-state key only",
    )
