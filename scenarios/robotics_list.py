"""The gymnasium-robotics scenario ids, read at registration without importing a simulator.

Presets and budgets: `advgame.scenarios.robotics`; the task base: `advgame.scenarios.robotics_task`.
"""

from __future__ import annotations

__all__ = ["ENVS", "FAMILIES"]

ENVS: dict[str, tuple[str, str]] = {
    "PointMaze_UMaze-v3": ("maze", "2-DoF ball reaching a goal in a U-shaped maze"),
    "PointMaze_Medium-v3": ("maze", "2-DoF ball reaching a goal in a medium maze"),
    "PointMaze_Large-v3": ("maze", "2-DoF ball reaching a goal in a large maze"),
    "AntMaze_UMaze-v5": ("maze", "8-DoF quadruped reaching a goal in a U-shaped maze"),
    "AntMaze_Medium-v5": ("maze", "8-DoF quadruped reaching a goal in a medium maze"),
    "AntMaze_Large-v5": ("maze", "8-DoF quadruped reaching a goal in a large maze"),
    "FetchReach-v4": ("fetch", "Fetch arm moving its gripper to a target"),
    "FetchPush-v4": ("fetch", "Fetch arm pushing a block to a target"),
    "FetchSlide-v4": ("fetch", "Fetch arm sliding a puck to a target out of reach"),
    "FetchPickAndPlace-v4": ("fetch", "Fetch arm picking a block and placing it at a target"),
    "HandReach-v3": ("hand", "Shadow Hand reaching fingertip targets"),
    "HandManipulateBlock-v1": ("hand", "Shadow Hand rotating a block to a target pose"),
    "HandManipulateEgg-v1": ("hand", "Shadow Hand rotating an egg to a target pose"),
    "HandManipulatePen-v1": ("hand", "Shadow Hand rotating a pen to a target pose"),
    "HandManipulateBlock_ContinuousTouchSensors-v1": (
        "hand",
        "block manipulation observing 92 continuous touch sensors",
    ),
    "HandManipulateEgg_BooleanTouchSensors-v1": (
        "hand",
        "egg manipulation observing 92 boolean touch sensors",
    ),
    "HandManipulatePen_BooleanTouchSensors-v1": (
        "hand",
        "pen manipulation observing 92 boolean touch sensors",
    ),
    "AdroitHandDoor-v1": ("adroit", "arm-mounted Shadow Hand opening a latched door"),
    "AdroitHandHammer-v1": ("adroit", "arm-mounted Shadow Hand hammering a nail"),
    "AdroitHandPen-v1": ("adroit", "arm-mounted Shadow Hand reorienting a pen"),
    "AdroitHandRelocate-v1": ("adroit", "arm-mounted Shadow Hand moving a ball to a target"),
    "FrankaKitchen-v1": ("kitchen", "Franka arm completing kitchen sub-tasks"),
}
"""Scenario id (the gymnasium-robotics id) -> (family, description)."""

FAMILIES = ("maze", "fetch", "hand", "adroit", "kitchen")
"""The robotics families, in registry order."""
