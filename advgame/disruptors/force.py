"""The external force disruptor: bounded forces (and torques) on named bodies, as in RARL."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from advgame.core.disruptor import AdditiveDisruptor, DisruptorSpec, as_budget
from advgame.errors import ConfigError

if TYPE_CHECKING:
    from advgame.core.task import MujocoSim, TaskBase

__all__ = ["ForceDisruptor", "ForceRuntime"]

AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True, kw_only=True)
class ForceDisruptor(DisruptorSpec):
    """Apply a bounded world-frame force to each named body (MuJoCo ``xfrc_applied``).

    The adversary controls ``len(bodies) * len(axes)`` components, each ``max_force * u`` newtons
    (and ``max_torque * u`` newton-metres for `torque_axes`). On a step the schedule skips, the
    force is removed unless the schedule holds it.

    Example:
        >>> import advgame
        >>> spec = ForceDisruptor(bodies=("torso",), axes="xz", max_force=5.0)
        >>> advgame.make("Hopper-v5", disruptors=[spec]).action_space("force_adversary").shape
        (2,)

    """

    kind = "force"
    budget_fields = ("max_force", "max_torque")
    bodies: Sequence[str] = ("torso",)
    """Bodies the forces act on (RARL: torso, feet, pole)."""
    axes: str = "xyz"
    """World axes of the force components, e.g. ``"xz"`` for planar tasks."""
    max_force: float | Sequence[float] = 1.0
    """Bound per force component (N), scalar or one per body."""
    torque_axes: str = ""
    """World axes of torque components (none by default)."""
    max_torque: float = 0.0
    """Bound per torque component (N·m)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if isinstance(self.bodies, str) or not self.bodies:
            raise ConfigError(
                f"bodies must be a non-empty sequence of body names, got {self.bodies!r}."
            )
        for axes in (self.axes, self.torque_axes):
            if any(a not in AXES for a in axes) or len(set(axes)) != len(axes):
                raise ConfigError(f"axes must be distinct letters from 'xyz', got {axes!r}.")
        if not self.axes and not self.torque_axes:
            raise ConfigError("A ForceDisruptor needs at least one force or torque axis.")
        as_budget(self.max_force, len(self.bodies), "ForceDisruptor.max_force")
        as_budget(self.max_torque, 1, "ForceDisruptor.max_torque")

    def build(self, task: TaskBase) -> ForceRuntime:
        """Bind to `task`'s MuJoCo model, resolving body names."""
        return ForceRuntime(self, task.sim)


class ForceRuntime(AdditiveDisruptor):
    """`ForceDisruptor` bound to a MuJoCo model."""

    hook = "environment"

    def __init__(self, spec: ForceDisruptor, sim: MujocoSim) -> None:
        self.ids = np.array([sim.body_id(b) for b in spec.bodies], dtype=np.int64)
        cols = [AXES[a] for a in spec.axes] + [3 + AXES[a] for a in spec.torque_axes]
        self.cols = np.array(cols, dtype=np.int64)
        force = as_budget(spec.max_force, len(spec.bodies), "ForceDisruptor.max_force")
        per_body = [
            np.concatenate(
                [np.full(len(spec.axes), f), np.full(len(spec.torque_axes), float(spec.max_torque))]
            )
            for f in force
        ]
        self.k = len(cols)
        self.hold = spec.schedule.hold
        self.wrench: np.ndarray | None = None
        super().__init__(spec, np.concatenate(per_body), bounded=True)

    def environment(self, sim: MujocoSim, u: np.ndarray | None) -> None:
        """Write the forces into ``xfrc_applied`` (zero them on a skipped, unheld step)."""
        if u is not None:
            self.wrench = self.perturbation(u).reshape(len(self.ids), self.k)
        elif not self.hold:
            self.wrench = None
        # rewritten every step: a recompiled model brings fresh data without the forces
        sim.data.xfrc_applied[np.ix_(self.ids, self.cols)] = (
            0.0 if self.wrench is None else self.wrench
        )

    def restore(self, sim: MujocoSim) -> None:
        """Remove the forces this disruptor applies."""
        self.wrench = None
        sim.data.xfrc_applied[np.ix_(self.ids, self.cols)] = 0.0
