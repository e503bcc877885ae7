"""robosuite environments advgame adds: MultiRobustDoor (a door, two arms).

Defining a subclass of a robosuite environment registers it with robosuite's in-process
registry (its ``EnvMeta`` metaclass), so `robosuite.make("MultiRobustDoor", ...)` works once
this module is imported; no installed file is touched.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from robosuite.environments.manipulation.door import Door

from advgame.errors import ConfigError

__all__ = ["ROBOT_Y_OFFSETS", "MultiRobustDoor"]

ROBOT_Y_OFFSETS = (-0.15, 0.25)
"""Side offsets (m) of the two robot bases: robot 0 opens the door, robot 1 stands beside it."""


class MultiRobustDoor(Door):
    """robosuite's Door task with a second single-arm robot beside the first.

    Robot 0 is the protagonist arm: the observations, shaped reward and success are robosuite's
    Door ones, computed for robot 0. Robot 1 reaches the same door and handle and can impede
    it; advgame drives it as an adversary agent (see `advgame.disruptors.ArmDisruptor`).
    """

    def __init__(self, robots: Any = ("Panda", "Panda"), **kwargs: Any) -> None:
        robots = [robots] * 2 if isinstance(robots, str) else list(robots)
        if len(robots) != 2:
            raise ConfigError(
                f"MultiRobustDoor needs exactly two robots (protagonist, adversary arm), got "
                f"{robots!r}; e.g. robots=['Panda', 'Panda']."
            )
        super().__init__(robots=robots, **kwargs)

    def _load_model(self) -> None:
        """Door's model, then both robot bases placed side by side at the table's edge."""
        super()._load_model()
        for robot, dy in zip(self.robots, ROBOT_Y_OFFSETS, strict=True):
            xpos = np.asarray(robot.robot_model.base_xpos_offset["table"](self.table_full_size[0]))
            robot.robot_model.set_base_xpos(xpos + np.array([0.0, dy, 0.0]))
