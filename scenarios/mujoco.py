"""Gymnasium MuJoCo v5 scenarios: every disruptor kind, the paper's settings, ATLA and RARL presets.

Presets of every MuJoCo scenario:

* ``default``: bounded observation (ε = 0.1, raw units) and action (ε = 0.1) adversaries.
* ``full``: every disruptor kind at once — observation, reward, action, a per-episode dynamics
  shift (mass, gravity, friction, damping, gear within ±20 % of nominal) and forces.
* ``rarl``: RARL-style forces on the bodies in `FORCES` (bounds chosen here, not RARL's).
* the paper's random-mode settings (``state-gauss-0.1``, ``action-gauss-0.15``, ...; see
  `advgame.scenarios.common.gaussian_presets`).
* ``atla`` (Ant, HalfCheetah, Hopper, Walker2d): an L∞ observation attack in the protagonist's
  normalized space with ATLA's budgets; ``obs-normalized-0.1`` the same attack with ε = 0.1 on
  every task.
* ``shift-deterministic``/``shift-uniform``/``shift-sinusoid`` (Ant, Humanoid: gravity and
  wind; Walker2d, Hopper: torso and foot lengths): the appendix's non-stationary settings as
  this module first read them. Hopper's 0.4 and 0.39 are taken as *full* capsule lengths
  centred on the nominal model (torso 0.4 ± 0.1, foot 0.39 ± 0.1) and Walker2d's half-lengths
  are doubled to full ones (torso 0.4 ± 0.2, feet 0.2 ± 0.1); the ``length`` parameter
  recompiles the model, so masses follow the lengths. Ant's and Humanoid's wind blows along +x
  at speed 0.8-1.2 in air of density 1.2 (no viscosity), and the sinusoid's episode index
  counts a policy's resets from 0. Results were measured with these presets, so they stay as
  they are; OMPO's own tasks are the ``ompo-*`` presets below, which differ: OMPO's numbers are
  half-lengths (Hopper's torso and foot 1.5-2.5 times nominal), its torso grows upward from the
  hip with masses unchanged, its wind blows along -x (Humanoid's at 0.5-1.5) in air of
  viscosity 0.00002, and its episode index starts at 1.
* ``ompo-nonstationary``, ``ompo-low``, ``ompo-mid``, ``ompo-high`` (Hopper, Walker2d, Ant,
  Humanoid): OMPO's non-stationary tasks from its authors' code, and fixed points of their
  ranges (`advgame.scenarios.ompo`, docs/ompo.md).

In an evaluation table, episode ``k`` of a job (seeds in order) plays episode ``k + 1`` of a
per-episode schedule, whatever its preset (`advgame.evaluation.table.jobs.schedule_index`), so
a ``shift-sinusoid`` or ``ompo-nonstationary`` column moves from seed to seed.
"""

from __future__ import annotations

from advgame.adversaries import ConstantAdversary, SinusoidAdversary, UniformAdversary
from advgame.core.registry import Preset
from advgame.core.schedule import Schedule
from advgame.disruptors import (
    ActionDisruptor,
    DynamicsDisruptor,
    ForceDisruptor,
    ObservationDisruptor,
    Param,
    RewardDisruptor,
)
from advgame.scenarios.common import gaussian_presets, make_task
from advgame.scenarios.ompo import ompo_presets

__all__ = ["ATLA_EPS", "FORCES", "dynamics_shift", "make_task", "presets"]

FORCES: dict[str, tuple[tuple[str, ...], str, float]] = {
    "Ant-v5": (("torso",), "xyz", 5.0),
    "HalfCheetah-v5": (("torso", "bfoot", "ffoot"), "xz", 5.0),
    "Hopper-v5": (("foot",), "xz", 3.0),
    "Walker2d-v5": (("foot", "foot_left"), "xz", 3.0),
    "Swimmer-v5": (("torso",), "xy", 1.0),
    "Humanoid-v5": (("torso",), "xyz", 10.0),
    "HumanoidStandup-v5": (("torso",), "xyz", 10.0),
    "Pusher-v5": (("object",), "xy", 0.5),
    "Reacher-v5": (("fingertip",), "xy", 0.05),
    "InvertedPendulum-v5": (("pole",), "x", 1.0),
    "InvertedDoublePendulum-v5": (("pole2",), "x", 1.0),
}
"""Force adversary per task: (bodies, world axes, bound per component in newtons)."""

ATLA_EPS = {"Ant-v5": 0.15, "HalfCheetah-v5": 0.15, "Hopper-v5": 0.075, "Walker2d-v5": 0.05}
"""ATLA's L∞ observation budgets in normalized units (Zhang et al. 2021)."""

_GRAVITY_WIND: dict = {  # Ant and Humanoid share the appendix's gravity and wind schedule
    "params": (Param("gravity", 9.81, 19.82), Param("wind", 0.8, 1.2)),
    "base": (14.715, 1.0),
    "amp": (4.905, 0.2),
    "freq": 0.5,
    "low": (9.81, 0.8),
    "high": (19.82, 1.2),
}
_SHIFTS: dict[str, dict] = {
    "Ant-v5": _GRAVITY_WIND,
    "Humanoid-v5": _GRAVITY_WIND,
    "Walker2d-v5": {
        "params": (
            Param("length", 0.2, 0.6, names=("torso",)),
            Param("length", 0.1, 0.3, names=("foot", "foot_left")),
        ),
        "base": (0.4, 0.2),
        "amp": (0.2, 0.1),
        "freq": 0.3,
        "low": (0.2, 0.1),
        "high": (0.6, 0.3),
    },
    "Hopper-v5": {
        "params": (
            Param("length", 0.3, 0.5, names=("torso",)),
            Param("length", 0.29, 0.49, names=("foot",)),
        ),
        "base": (0.4, 0.39),
        "amp": (0.1, 0.1),
        "freq": 0.2,
        "low": (0.3, 0.29),
        "high": (0.5, 0.49),
    },
}


def _force(env_id: str, scale: float = 1.0) -> ForceDisruptor:
    bodies, axes, bound = FORCES[env_id]
    return ForceDisruptor(bodies=bodies, axes=axes, max_force=bound * scale)


def dynamics_shift() -> DynamicsDisruptor:
    """A per-episode shift of mass, gravity, friction, damping and gear within ±20 % of nominal."""
    params = tuple(
        Param(k, 0.8, 1.2, relative=True)
        for k in ("mass", "gravity", "friction", "damping", "gear")
    )
    return DynamicsDisruptor(params=params, schedule=Schedule.per_episode())


def _shift_presets(env_id: str) -> dict[str, Preset]:
    s = _SHIFTS[env_id]
    spec = DynamicsDisruptor(params=s["params"], schedule=Schedule.per_episode())
    what = " and ".join(sorted({p.kind for p in s["params"]}))
    return {
        "shift-deterministic": Preset(
            (spec,),
            {"dynamics_adversary": ConstantAdversary(s["base"])},
            f"appendix: fixed {what} shift {s['base']}",
        ),
        "shift-uniform": Preset(
            (spec,),
            {"dynamics_adversary": UniformAdversary(s["low"], s["high"])},
            f"appendix: {what} ~ U({s['low']}, {s['high']}) per episode",
        ),
        "shift-sinusoid": Preset(
            (spec,),
            {"dynamics_adversary": SinusoidAdversary(s["base"], s["amp"], s["freq"])},
            f"appendix: {what} = {s['base']} + {s['amp']}·sin({s['freq']}·episode)",
        ),
    }


def presets(env_id: str) -> dict[str, Preset]:
    """The presets of MuJoCo scenario `env_id` (see the module docstring)."""
    out = {
        "default": Preset(
            (ObservationDisruptor(eps=0.1), ActionDisruptor(eps=0.1)),
            description="bounded observation and action adversaries, ε = 0.1",
        ),
        "full": Preset(
            (
                ObservationDisruptor(eps=0.1),
                RewardDisruptor(eps=0.1),
                ActionDisruptor(eps=0.1),
                dynamics_shift(),
                _force(env_id),
            ),
            description="every disruptor kind: observation, reward, action, dynamics, force",
        ),
        "rarl": Preset(
            (_force(env_id),),
            description="RARL-style bounded forces on " + ", ".join(FORCES[env_id][0]),
        ),
        **gaussian_presets(),
    }
    out["obs-normalized-0.1"] = Preset(
        (ObservationDisruptor(eps=0.1, space="normalized"),),
        description="ATLA-style L∞ observation attack, ε = 0.1 in normalized units (any task)",
    )
    if env_id in ATLA_EPS:
        out["atla"] = Preset(
            (ObservationDisruptor(eps=ATLA_EPS[env_id], space="normalized"),),
            description=f"ATLA: L∞ observation attack, ε = {ATLA_EPS[env_id]} in normalized units",
        )
    if env_id in _SHIFTS:
        out.update(_shift_presets(env_id))
    out.update(ompo_presets(env_id))
    return out
