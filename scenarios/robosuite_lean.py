"""A robosuite robot's action size computed once a controller, not three times a substep.

robosuite 1.5 steps a control step as 25 simulator substeps (20 Hz control on 500 Hz physics),
and at each substep ``RobotEnv._pre_action`` reads every robot's ``action_dim`` twice (to cut
the robot's part of the action) and ``FixedBaseRobot.control`` once more (its assertion).
``action_dim`` is a property that rebuilds the robot's action bounds each time, concatenating
every part controller's limits with NumPy: 8.7 % of an RS-DoorCausal step under random actions
(py-spy, 7 Dec 2026, 6,000 moves), more than MuJoCo's ``mj_step2``.

`lean_robots` gives each robot of robosuite's `FixedBaseRobot` class (Panda, Sawyer, IIWA, UR5e,
Jaco, Kinova3, Baxter: every arm of this package's robosuite scenarios) the subclass
`LeanFixedBaseRobot`, whose ``action_dim`` is the same property's value, kept while the robot
has the same composite controller object (robosuite makes a new one when it loads a controller)
and the same controllers in it. Nothing else changes: the same assertion, the same slices, the
same values (``tests/test_robosuite_lean.py`` plays games with and without it, bit for bit).
Robots of other classes (mobile and legged bases) keep theirs.
"""

from __future__ import annotations

from typing import Any

from robosuite.robots.fixed_base_robot import FixedBaseRobot

__all__ = ["LeanFixedBaseRobot", "lean_robots"]


class LeanFixedBaseRobot(FixedBaseRobot):
    """robosuite's `FixedBaseRobot` with ``action_dim`` kept per composite controller."""

    @property
    def action_dim(self) -> int:
        """``FixedBaseRobot.action_dim``, computed again only when the controllers change."""
        composite = self.composite_controller
        parts = tuple(getattr(composite, "part_controllers", {}).values())
        kept = self.__dict__.get("_lean_action_dim")
        if kept is None or kept[0] is not composite or kept[1] != parts:
            kept = (composite, parts, int(FixedBaseRobot.action_dim.fget(self)))
            self.__dict__["_lean_action_dim"] = kept
        return kept[2]


def lean_robots(env: Any) -> int:
    """Give each `FixedBaseRobot` of robosuite env `env` the lean class; return how many."""
    swapped = 0
    for robot in getattr(env, "robots", ()):
        if type(robot) is FixedBaseRobot:
            robot.__class__ = LeanFixedBaseRobot
            swapped += 1
    return swapped
