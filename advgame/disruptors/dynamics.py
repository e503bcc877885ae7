"""The dynamics disruptor (internal shift): masses, gravity, wind, friction, damping, gear, lengths.

Each `Param` is one adversary action dimension, mapped linearly from ``[-1, 1]`` onto its
interval ``[low, high]`` (absolute units, or factors of the nominal value if ``relative``).
Nominal values are snapshotted when the game is built and written back on every reset (MuJoCo
keeps model edits across ``env.reset()``) unless the schedule says the shift persists.
Body lengths come in two kinds. ``length`` changes the capsule's half-length in an
`mujoco.MjSpec` and recompiles the model, so mass, inertia and contacts all follow.
``capsule`` is OMPO's shape change: the half-length (and, with ``anchor="base"``, the body's
position) written into the live model with masses and inertias left nominal, and the collision
bounds updated so contacts follow the shape (`advgame.disruptors.capsule`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from advgame.core.disruptor import Disruptor, DisruptorSpec
from advgame.core.fields import check_fields
from advgame.disruptors.capsule import CapsuleEdit
from advgame.errors import BudgetError, ConfigError, UnknownNameError, did_you_mean

if TYPE_CHECKING:
    from advgame.core.task import MujocoSim, TaskBase

__all__ = ["DynamicsDisruptor", "DynamicsRuntime", "Param"]

KINDS = ("mass", "gravity", "wind", "friction", "damping", "gear", "length", "capsule")
# Which model object each kind names in `Param.names` (None: a global option, no names).
NAMED = {
    "mass": "body",
    "length": "body",
    "capsule": "body",
    "friction": "geom",
    "damping": "joint",
    "gear": "actuator",
    "gravity": None,
    "wind": None,
}


@dataclass(frozen=True)
class Param:
    """One dynamics parameter under the adversary's control, and its interval.

    Example:
        >>> Param("gravity", 9.81, 19.62).kind
        'gravity'

    """

    kind: Literal["mass", "gravity", "wind", "friction", "damping", "gear", "length", "capsule"]
    """What is changed: body ``mass`` (inertia scaled with it), ``gravity`` magnitude, ``wind``
    speed along `axis` (with `air_density`), sliding ``friction``, joint ``damping``, actuator
    ``gear``, the full ``length`` of a body's capsule (recompiled: mass follows), or the
    ``capsule`` half-length edited in place as OMPO does (masses nominal; see `anchor`)."""
    low: float
    """Lower end of the interval (absolute, or a factor of nominal if `relative`)."""
    high: float
    """Upper end of the interval."""
    names: Sequence[str] = ()
    """Bodies (mass, length), geoms (friction), joints (damping) or actuators (gear) it applies
    to; empty means all of them. Must be empty for gravity and wind."""
    relative: bool = False
    """Interpret `low`/`high` as factors of each target's nominal value."""
    air_density: float = 1.2
    """``wind`` only: the medium density (kg/m³) set while the wind blows (value ≠ nominal);
    MuJoCo's default is 0, a vacuum in which wind has no effect."""
    air_viscosity: float | None = None
    """``wind`` only: the medium viscosity (Pa·s) set while the wind blows; None keeps the
    model's own (MuJoCo's default 0). OMPO's Ant and Humanoid use 0.00002."""
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    """``wind`` only: the unit vector the wind blows along; the value is its speed (the wind's
    component along `axis`; the other components stay nominal). OMPO's blows along -x."""
    anchor: Literal["centre", "base"] = "centre"
    """``capsule`` only: what stays in place, the capsule's centre or its base (the end at -z
    of the geom's frame, with the body's children): OMPO's torso grows up from the hip."""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise UnknownNameError(
                f"Unknown dynamics parameter {self.kind!r}.{did_you_mean(self.kind, KINDS)} "
                f"Known: {KINDS}."
            )
        check_fields(self)
        lo, hi = float(self.low), float(self.high)
        if not (np.isfinite(lo) and np.isfinite(hi)) or lo > hi:
            raise BudgetError(
                f"Param({self.kind!r}) needs finite low <= high, got low={self.low!r}, high={self.high!r}."
            )
        if self.kind in ("mass", "friction", "damping", "length", "capsule", "gravity") and lo < 0:
            raise BudgetError(f"Param({self.kind!r}) cannot be negative, got low={self.low!r}.")
        if self.kind in ("mass", "length", "capsule") and lo == 0 and not self.relative:
            raise BudgetError(f"Param({self.kind!r}) must be > 0, got low={self.low!r}.")
        if isinstance(self.names, str):
            raise ConfigError(
                f"Param.names must be a sequence of names, got the string {self.names!r}."
            )
        if NAMED[self.kind] is None and tuple(self.names):
            raise ConfigError(
                f"Param({self.kind!r}) is global and takes no names, got {self.names!r}."
            )
        self._check_options()

    def _check_options(self) -> None:
        """The kind-specific options: set only on their kind, and in range."""
        wind = self.air_viscosity is not None or tuple(self.axis) != (1.0, 0.0, 0.0)
        if wind and self.kind != "wind":
            raise ConfigError(f"air_viscosity and axis are wind options, not {self.kind!r}'s.")
        if self.anchor != "centre" and self.kind != "capsule":
            raise ConfigError(f"anchor is an option of Param('capsule'), not {self.kind!r}'s.")
        axis = np.asarray(self.axis, dtype=np.float64)
        if not np.isfinite(axis).all() or abs(float(np.linalg.norm(axis)) - 1.0) > 1e-9:
            raise ConfigError(f"Param.axis must be a unit vector, got {self.axis!r}.")
        if self.air_viscosity is not None and not self.air_viscosity >= 0:
            raise ConfigError(f"Param.air_viscosity must be >= 0, got {self.air_viscosity!r}.")


@dataclass(frozen=True, kw_only=True)
class DynamicsDisruptor(DisruptorSpec):
    """Shift internal model parameters within intervals (the paper's internal dynamic shift).

    Parameters set on an active step stay in force until the next active step or the end of
    the episode.

    Example:
        >>> import advgame
        >>> spec = DynamicsDisruptor(params=[Param("gravity", 9.81, 19.62)])
        >>> advgame.make("Ant-v5", disruptors=[spec]).action_space("dynamics_adversary").shape
        (1,)

    """

    kind = "dynamics"
    params: Sequence[Param] = field(default_factory=tuple)
    """The parameters, one adversary action dimension each."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.params or not all(isinstance(p, Param) for p in self.params):
            raise ConfigError("DynamicsDisruptor.params must be a non-empty sequence of Param.")
        if self.schedule.persist and any(p.kind == "length" for p in self.params):
            raise ConfigError("A persistent (persist=True) length shift is not supported.")

    def build(self, task: TaskBase) -> DynamicsRuntime:
        """Bind to `task`'s MuJoCo model, resolving names and snapshotting nominal values."""
        return DynamicsRuntime(self, task.sim)


class _Bound:
    """A Param resolved against one model: ids and nominal values."""

    def __init__(self, p: Param, sim: MujocoSim) -> None:
        self.p = p
        model = sim.model
        kind = NAMED[p.kind]
        if kind and not p.names and p.kind in ("length", "capsule"):
            raise ConfigError(f"Param({p.kind!r}) needs the bodies to lengthen in names=(...).")
        if kind and not p.names:  # every object of that kind (bodies: all but the world)
            count = {
                "body": model.nbody,
                "geom": model.ngeom,
                "joint": model.njnt,
                "actuator": model.nu,
            }[kind]
            self.ids = np.arange(1 if kind == "body" else 0, count, dtype=np.int64)
        elif kind:
            ids = {
                "body": sim.body_id,
                "geom": sim.geom_id,
                "joint": sim.joint_id,
                "actuator": sim.actuator_id,
            }[kind]
            self.ids = np.array([ids(n) for n in p.names], dtype=np.int64)
        else:
            self.ids = np.zeros(0, dtype=np.int64)
        if p.kind == "damping":  # every degree of freedom of the joints (ball: 3, free: 6)
            self.ids = np.nonzero(np.isin(model.dof_jntid, self.ids))[0].astype(np.int64)
        if p.kind == "length":
            self.geoms = [_capsule_of(sim, n) for n in p.names]
        if p.kind == "capsule":
            self.edits = [
                CapsuleEdit(model, int(i), n, p.anchor)
                for i, n in zip(self.ids, p.names, strict=True)
            ]
        self.nominal = self._read(sim)

    def _read(self, sim: MujocoSim) -> dict[str, np.ndarray]:
        m, k = sim.model, self.p.kind
        if k == "mass":
            return {
                "mass": m.body_mass[self.ids].copy(),
                "inertia": m.body_inertia[self.ids].copy(),
            }
        if k == "gravity":
            return {"gravity": m.opt.gravity.copy()}
        if k == "wind":
            return {
                "wind": m.opt.wind.copy(),
                "density": np.array([m.opt.density]),
                "viscosity": np.array([m.opt.viscosity]),
            }
        if k == "friction":
            return {"friction": m.geom_friction[self.ids, 0].copy()}
        if k == "damping":
            return {"damping": m.dof_damping[self.ids].copy()}
        if k == "gear":
            return {"gear": m.actuator_gear[self.ids, 0].copy()}
        if k == "capsule":
            return {"half": np.array([e.half for e in self.edits])}
        return {"half": np.array([g.size[1] for g in self.geoms])}

    def reference(self) -> np.ndarray:
        """The nominal value(s) in the parameter's own units (absolute)."""
        k = self.p.kind
        if k == "gravity":
            return np.array([-self.nominal["gravity"][2]])
        if k == "wind":
            return np.array([self.nominal["wind"] @ np.asarray(self.p.axis, dtype=np.float64)])
        if k == "length":
            return 2.0 * self.nominal["half"]
        return next(iter(self.nominal.values()))

    def apply(self, sim: MujocoSim, value: float) -> None:
        """Write `value` into the live model (lengths are handled by the runtime)."""
        m, k, nom = sim.model, self.p.kind, self.nominal
        nom_values = self.reference()
        target = nom_values * value if self.p.relative else np.full_like(nom_values, value)
        if k == "mass":
            m.body_mass[self.ids] = target
            ratio = np.where(nom["mass"] > 0, target / np.where(nom["mass"] > 0, nom["mass"], 1), 1)
            m.body_inertia[self.ids] = nom["inertia"] * ratio[:, None]
        elif k == "gravity":
            m.opt.gravity[2] = -float(target[0])
        elif k == "wind":
            axis = np.asarray(self.p.axis, dtype=np.float64)  # the default x: wind[0] = target
            m.opt.wind[:] = nom["wind"] - (nom["wind"] @ axis) * axis + float(target[0]) * axis
            still = float(target[0]) == float(nom_values[0])
            m.opt.density = float(nom["density"][0]) if still else float(self.p.air_density)
            viscosity = self.p.air_viscosity
            m.opt.viscosity = float(
                nom["viscosity"][0] if still or viscosity is None else viscosity
            )
        elif k == "friction":
            m.geom_friction[self.ids, 0] = target
        elif k == "damping":
            m.dof_damping[self.ids] = target
        elif k == "gear":
            m.actuator_gear[self.ids, 0] = target
        elif k == "capsule":
            for e, half in zip(self.edits, target, strict=True):
                e.apply(m, float(half))
        else:
            for g, full in zip(self.geoms, target, strict=True):
                size = np.array(g.size)
                size[1] = full / 2.0
                g.size = size

    def restore(self, sim: MujocoSim) -> None:
        """Write the nominal values back into the live model."""
        m, k, nom = sim.model, self.p.kind, self.nominal
        if k == "mass":
            m.body_mass[self.ids] = nom["mass"]
            m.body_inertia[self.ids] = nom["inertia"]
        elif k == "gravity":
            m.opt.gravity[:] = nom["gravity"]
        elif k == "wind":
            m.opt.wind[:] = nom["wind"]
            m.opt.density = float(nom["density"][0])
            m.opt.viscosity = float(nom["viscosity"][0])
        elif k == "friction":
            m.geom_friction[self.ids, 0] = nom["friction"]
        elif k == "damping":
            m.dof_damping[self.ids] = nom["damping"]
        elif k == "gear":
            m.actuator_gear[self.ids, 0] = nom["gear"]
        elif k == "capsule":
            for e in self.edits:
                e.restore(m)
        else:
            for g, half in zip(self.geoms, nom["half"], strict=True):
                size = np.array(g.size)
                size[1] = half
                g.size = size


def _capsule_of(sim: MujocoSim, body: str) -> Any:
    """The spec geom of `body` whose length the disruptor changes: its first capsule/cylinder."""
    import mujoco

    sim.body_id(body)  # clear error for an unknown body
    kinds = (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER)
    for g in sim.spec.body(body).geoms:
        if g.type in kinds:
            return g
    raise ConfigError(f"Body {body!r} has no capsule or cylinder geom whose length could change.")


class DynamicsRuntime(Disruptor):
    """`DynamicsDisruptor` bound to a MuJoCo model."""

    hook = "environment"
    edits_model = True
    """It changes the model (and may recompile it), so the game applies it before data edits."""

    def __init__(self, spec: DynamicsDisruptor, sim: MujocoSim) -> None:
        self.params = [_Bound(p, sim) for p in spec.params]
        self.low = np.array([p.low for p in spec.params], dtype=np.float64)
        self.high = np.array([p.high for p in spec.params], dtype=np.float64)
        self.nominal_values = np.array([self._nominal(b) for b in self.params])
        """Each parameter's nominal value in its own units (NaN where targets differ)."""
        self.current: np.ndarray | None = None
        self._epoch = sim.epoch
        super().__init__(spec, len(self.params), bounded=True)

    def values(self, u: np.ndarray) -> np.ndarray:
        """Parameter values for a (decoded) action.

        A value within float32 resolution of the nominal one is the nominal value exactly, so
        the no-op action (a float32) reproduces the nominal model bit for bit.
        """
        v = self.low + (u + 1.0) * 0.5 * (self.high - self.low)
        nom = self.nominal_values
        close = np.abs(v - nom) <= 1e-6 * np.maximum(1.0, np.abs(nom))  # False where nom is NaN
        return np.where(close, nom, v)

    def encode(self, value: Any) -> np.ndarray:
        """Parameter values (absolute, or factors if relative) -> adversary action."""
        v = np.asarray(value, dtype=np.float64).reshape(self._batch_shape(value))
        span = self.high - self.low
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(span > 0, 2.0 * (v - self.low) / np.where(span > 0, span, 1.0) - 1.0, 0.0)
        return u.astype(np.float32)

    @property
    def noop_action(self) -> np.ndarray:
        """The action nearest the nominal model (exactly nominal when it lies in the interval)."""
        nominal = [1.0 if b.p.relative else float(b.reference()[0]) for b in self.params]
        return np.clip(self.encode(nominal), -1.0, 1.0)

    @staticmethod
    def _nominal(b: _Bound) -> float:
        if b.p.relative:
            return 1.0
        ref = b.reference()
        return float(ref[0]) if ref.size and np.all(ref == ref[0]) else float("nan")

    def environment(self, sim: MujocoSim, u: np.ndarray | None) -> None:
        """Set the parameters on an active step; re-apply them if the model was recompiled."""
        if u is not None:
            self.current = self.values(u)
            self._write(sim)
        elif self.current is not None and sim.epoch != self._epoch:
            self._write(sim)

    def _write(self, sim: MujocoSim) -> None:
        assert self.current is not None
        lengths = [
            (b, v) for b, v in zip(self.params, self.current, strict=True) if b.p.kind == "length"
        ]
        if lengths:
            for b, v in lengths:
                b.apply(sim, float(v))
            sim.recompile()
        for b, v in zip(self.params, self.current, strict=True):
            if b.p.kind != "length":
                b.apply(sim, float(v))
        self._epoch = sim.epoch

    def restore(self, sim: MujocoSim) -> None:
        """Write every nominal value back and forget the current shift."""
        for b in self.params:
            b.restore(sim)
        self.current = None
        self._epoch = sim.epoch
