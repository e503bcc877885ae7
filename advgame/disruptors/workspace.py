"""The workspace disruptor (external, per episode): where things stand and what colour they are.

Each `Shift` is one adversary action dimension ``u ∈ [-1, 1]``. It moves bodies by ``u·offset``
(metres, world frame), turns them by ``u·yaw`` about the vertical through their own origin, and
recolours geoms from their nominal colour (``u = 0``) towards ``rgba_high`` (``u = 1``) or
``rgba_low`` (``u = -1``). Several effects on one dimension are *correlated* disturbances (the
``door-shift`` preset moves the door away and the handle up together); the paper's causal tasks
put a causal and a spurious feature on two dimensions (`advgame.scenarios.robosuite_causal`).

The adversary chooses once per episode, at reset, in a *setup move* of its own (before the
protagonist's first observation, which shows the disturbed workspace). Fixed bodies move through
``model.body_pos`` and ``model.body_quat``; bodies on a free joint (objects) through their
``qpos``; colours through ``model.geom_rgba``. The model edits are written back on the next
reset, so a nominal reset is the nominal workspace again.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from advgame.core.disruptor import Disruptor, DisruptorSpec
from advgame.core.fields import check_fields
from advgame.errors import BudgetError, ConfigError

if TYPE_CHECKING:
    from advgame.core.task import MujocoSim, TaskBase

__all__ = ["Shift", "WorkspaceDisruptor", "WorkspaceRuntime"]


@dataclass(frozen=True)
class Shift:
    """One adversary dimension of a workspace disturbance: what moves and what changes colour.

    Example:
        >>> Shift("door", bodies=["Door_main"], offset=(0.1, 0.0, 0.0)).offset
        (0.1, 0.0, 0.0)

    """

    name: str
    """A label for reports (``"table_z"``, ``"door"``)."""
    bodies: Sequence[str] = ()
    """Bodies moved by ``u·offset`` (all of them by the same vector)."""
    offset: Sequence[float] = (0.0, 0.0, 0.0)
    """World-frame displacement (metres) at ``u = 1``."""
    body_offsets: Sequence[tuple[str, Sequence[float]]] = ()
    """Further bodies with their own displacement at ``u = 1`` (correlated moves)."""
    geoms: Sequence[str] = ()
    """Geoms recoloured with this dimension."""
    rgba_high: Sequence[float] = (0.0, 0.0, 1.0, 1.0)
    """Colour of `geoms` at ``u = 1`` (nominal at ``u = 0``, linear in between)."""
    rgba_low: Sequence[float] = (0.0, 1.0, 0.0, 1.0)
    """Colour of `geoms` at ``u = -1``."""
    yaw: float = 0.0
    """Turn (radians) of `bodies` at ``u = 1``, about the z axis through each body's origin (the
    parent frame's z: the world's for top-level bodies and free objects)."""

    def __post_init__(self) -> None:
        check_fields(self)
        moves = [tuple(self.offset), *(tuple(o) for _, o in self.body_offsets)]
        for o in moves:
            if len(o) != 3 or not np.all(np.isfinite(o)):
                raise BudgetError(
                    f"Shift {self.name!r}: offsets must be 3 finite numbers, got {o!r}."
                )
        for c in (self.rgba_high, self.rgba_low):
            if len(c) != 4 or not all(0.0 <= float(x) <= 1.0 for x in c):
                raise BudgetError(
                    f"Shift {self.name!r}: colours are 4 values in [0, 1], got {c!r}."
                )
        if not np.isfinite(self.yaw) or (self.yaw != 0.0 and not self.bodies):
            raise BudgetError(
                f"Shift {self.name!r}: yaw turns `bodies`; it must be finite and needs at least "
                f"one body, got yaw={self.yaw!r}, bodies={tuple(self.bodies)!r}."
            )
        if isinstance(self.bodies, str) or isinstance(self.geoms, str):
            raise ConfigError(f"Shift {self.name!r}: bodies and geoms are lists of names.")
        if not (self.bodies or self.body_offsets or self.geoms):
            raise ConfigError(f"Shift {self.name!r} moves and recolours nothing.")

    def moves(self) -> list[tuple[str, np.ndarray, float]]:
        """Every (body, displacement at ``u = 1``, turn at ``u = 1``)."""
        out = [(b, np.asarray(self.offset, dtype=np.float64), float(self.yaw)) for b in self.bodies]
        out += [(b, np.asarray(o, dtype=np.float64), 0.0) for b, o in self.body_offsets]
        return out


@dataclass(frozen=True, kw_only=True)
class WorkspaceDisruptor(DisruptorSpec):
    """Per-episode workspace changes chosen by an adversary at reset (table, door, objects).

    Example:
        >>> spec = WorkspaceDisruptor(shifts=[Shift("table_z", bodies=["table"], offset=(0, 0, 0.03))])
        >>> spec.agent
        'workspace_adversary'

    """

    kind = "workspace"
    shifts: Sequence[Shift] = field(default_factory=tuple)
    """The dimensions of the adversary's action, one `Shift` each."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.shifts or not all(isinstance(s, Shift) for s in self.shifts):
            raise ConfigError("WorkspaceDisruptor.shifts must be a non-empty sequence of Shift.")
        if self.schedule.persist:
            raise ConfigError(
                "A workspace disturbance lasts one episode; persist=True is not supported."
            )

    def build(self, task: TaskBase) -> WorkspaceRuntime:
        """Bind to `task`: resolve body and geom names on its MuJoCo model."""
        return WorkspaceRuntime(self, task.sim)


class _Move:
    """One body's move per unit of its dimension: a fixed body (model) or a free joint (qpos)."""

    def __init__(self, sim: MujocoSim, name: str, delta: np.ndarray, yaw: float) -> None:
        import mujoco

        self.name, self.delta, self.yaw = name, delta, yaw
        self.body = sim.body_id(name)
        m = sim.model
        jnt = int(m.body_jntadr[self.body])
        self.free = jnt >= 0 and int(m.jnt_type[jnt]) == int(mujoco.mjtJoint.mjJNT_FREE)
        self.qpos = int(m.jnt_qposadr[jnt]) if self.free else -1


class WorkspaceRuntime(Disruptor):
    """`WorkspaceDisruptor` bound to a MuJoCo model; applied once, in the game's setup move."""

    hook = "environment"
    at_reset = True
    """The game plays it in a setup move after the task's reset, before anyone else moves."""

    def __init__(self, spec: WorkspaceDisruptor, sim: MujocoSim) -> None:
        self.dims = [[_Move(sim, b, d, y) for b, d, y in s.moves()] for s in spec.shifts]
        self.colours = [
            (
                np.array([sim.geom_id(g) for g in s.geoms], dtype=np.int64),
                np.asarray(s.rgba_high, dtype=np.float64),
                np.asarray(s.rgba_low, dtype=np.float64),
            )
            for s in spec.shifts
        ]
        self._saved: list[tuple[str, int, np.ndarray]] = []
        self.applied: np.ndarray | None = None
        """The action applied this episode (``None`` when nothing was applied)."""
        super().__init__(spec, len(spec.shifts), bounded=True)

    def environment(self, sim: MujocoSim, u: np.ndarray | None) -> None:
        """Move and recolour for action `u` (once, at the setup move); `None` changes nothing."""
        if u is None:
            return
        m, d = sim.model, sim.data
        for value, moves, (geoms, high, low) in zip(u, self.dims, self.colours, strict=True):
            v = float(value)
            for mv in moves:
                delta = v * mv.delta
                if mv.free:
                    d.qpos[mv.qpos : mv.qpos + 3] += delta
                else:
                    self._save(sim, "body_pos", mv.body)
                    m.body_pos[mv.body] += delta
                sim.body_moved(mv.name, delta)
                if mv.yaw:
                    self._turn(sim, mv, v * mv.yaw)
            if geoms.size:
                for g in geoms:
                    self._save(sim, "geom_rgba", int(g))
                nominal = m.geom_rgba[geoms]
                target = high if v >= 0 else low
                m.geom_rgba[geoms] = nominal + abs(v) * (target - nominal)
        self.applied = np.array(u, dtype=np.float64)

    def _turn(self, sim: MujocoSim, mv: _Move, angle: float) -> None:
        """Turn body `mv` by `angle` about the world z axis through its origin."""
        import mujoco

        turn = np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])
        if mv.free:
            quat = sim.data.qpos[mv.qpos + 3 : mv.qpos + 7]
        else:
            self._save(sim, "body_quat", mv.body)
            quat = sim.model.body_quat[mv.body]
        out = np.empty(4)
        mujoco.mju_mulQuat(out, turn, quat.copy())
        quat[:] = out

    def _save(self, sim: MujocoSim, field_name: str, idx: int) -> None:
        self._saved.append((field_name, idx, getattr(sim.model, field_name)[idx].copy()))

    def restore(self, sim: MujocoSim) -> None:
        """Write back every edited model value (in reverse order), and undo cache moves."""
        m = sim.model
        for field_name, idx, nominal in reversed(self._saved):
            getattr(m, field_name)[idx] = nominal
        for v, moves in zip(
            self.applied if self.applied is not None else [], self.dims, strict=False
        ):
            for mv in moves:
                sim.body_moved(mv.name, -float(v) * mv.delta)
        self._saved = []
        self.applied = None
