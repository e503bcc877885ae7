"""The arm disruptor (external): a second robot arm in the scene, driven by an adversary agent.

The task base names the robots the protagonist does not control (``external_robots`` of a
robosuite task) and holds their commands in ``task.external_actions``. An `ArmDisruptor` gives
one of them to an adversary: its action ``u ∈ [-1, 1]^k`` (k = that arm's controller action
size) becomes the arm's command ``scale ⊙ u`` on every step its schedule is active, and zero
(the controller's hold command) on the others. Its payoff is the negative of the protagonist's
true payoff, like every adversary's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from advgame.core.disruptor import Disruptor, DisruptorSpec, as_budget
from advgame.errors import ConfigError

if TYPE_CHECKING:
    from advgame.core.task import MujocoSim, TaskBase

__all__ = ["ArmDisruptor", "ArmRuntime"]


@dataclass(frozen=True, kw_only=True)
class ArmDisruptor(DisruptorSpec):
    """An adversarial robot arm: the adversary commands an external robot of the task.

    Example:
        >>> ArmDisruptor(robot=1, scale=0.5).agent
        'arm_adversary'

    """

    kind = "arm"
    budget_fields = ("scale",)
    robot: int = 1
    """Index of the external robot (in the task's robot order) the adversary commands."""
    scale: float | tuple[float, ...] = 1.0
    """Budget: the command is ``scale ⊙ u`` in the arm controller's own normalized units
    (robosuite's action range is [-1, 1]); scalar or one value per action dimension."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if int(self.robot) != self.robot or self.robot < 0:
            raise ConfigError(f"ArmDisruptor.robot must be a robot index >= 0, got {self.robot!r}.")

    def build(self, task: TaskBase) -> ArmRuntime:
        """Bind to `task`'s external robot `robot`."""
        commands = getattr(task, "external_actions", None)
        if not commands or self.robot not in commands:
            have = sorted(commands) if commands else []
            raise ConfigError(
                f"{type(task).__name__} has no external robot {self.robot} (external robots: "
                f"{have}); an ArmDisruptor needs a task with a second arm, e.g. MultiRobustDoor."
            )
        return ArmRuntime(self, commands[self.robot])


class ArmRuntime(Disruptor):
    """`ArmDisruptor` bound to one external arm's command buffer."""

    hook = "environment"
    edits_model = False

    def __init__(self, spec: ArmDisruptor, command: np.ndarray) -> None:
        self.command = command
        self.unit = as_budget(spec.scale, command.size, "ArmDisruptor.scale")
        if np.any(self.unit > 1.0):
            raise ConfigError(
                f"ArmDisruptor.scale must lie in [0, 1] (the controller's range), got {spec.scale!r}."
            )
        super().__init__(spec, command.size, bounded=True)

    def encode(self, value: Any) -> np.ndarray:
        """An arm command (controller units) -> adversary action."""
        v = np.asarray(value, dtype=np.float64).reshape(self._batch_shape(value))
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(self.unit > 0, v / np.where(self.unit > 0, self.unit, 1.0), 0.0)
        return u.astype(np.float32)

    def environment(self, sim: MujocoSim, u: np.ndarray | None) -> None:
        """Set the arm's command for the coming step (zero on a step the schedule skips)."""
        if u is None:
            self.command[:] = 0.0
        else:
            self.command[:] = self.unit * u

    def restore(self, sim: MujocoSim) -> None:
        """Zero the command (the task also zeroes it on reset)."""
        self.command[:] = 0.0
