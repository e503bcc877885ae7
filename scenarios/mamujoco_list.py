"""The MaMuJoCo scenario table: the paper's multi-agent factorizations, and which of them work here.

Every row of the paper's multi-agent table (Robust Gymnasium, appendix, "A List of Examples for
Robustness in Multi-Agent Tasks") is a `Variant` of ``gymnasium_robotics.mamujoco_v1``, registered
as ``"MA-<scenario>-<agent_conf>"`` in the ``"mamujoco"`` family, unless it fails with the pinned
versions (gymnasium-robotics 1.4.2, MuJoCo 3.9.0). The failing ones are listed in `BROKEN`
(the factorization exists upstream but fails to build or step) or `UNAVAILABLE` (gymnasium-robotics
does not offer the factorization), each with the exact error observed, and are not registered; the
tests assert that they still fail that way, so an upstream fix shows up as a test failure that
says to move the row.

This module imports no simulator: listing scenarios stays cheap. The task base and presets live
in `advgame.scenarios.mamujoco`.
"""

from __future__ import annotations

from dataclasses import dataclass

from advgame.core.registry import ScenarioSpec, list_scenarios, register, scenario_spec
from advgame.errors import ConfigError

__all__ = ["BROKEN", "FAMILY", "UNAVAILABLE", "VARIANTS", "Variant", "register_all", "working"]

FAMILY = "mamujoco"
"""The registry family of every MaMuJoCo scenario."""

_MODULE = "advgame.scenarios.mamujoco"


@dataclass(frozen=True)
class Variant:
    """One factorization of a MuJoCo robot into cooperating agents."""

    scenario: str
    """The MaMuJoCo scenario name (``"HalfCheetah"``, ``"ManySegmentAnt"``, ...)."""
    agent_conf: str
    """The factorization, e.g. ``"2x3"`` (two agents of three joints each)."""
    description: str
    """One line for `advgame list`."""

    @property
    def id(self) -> str:
        """The registry id, ``"MA-<scenario>-<agent_conf>"``."""
        return f"MA-{self.scenario}-{self.agent_conf}"


_ROWS = (
    Variant("Ant", "2x4", "quadruped, 2 agents: front legs | back legs"),
    Variant("Ant", "2x4d", "quadruped, 2 agents: diagonal leg pairs"),
    Variant("Ant", "4x2", "quadruped, 4 agents: one leg (hip + ankle) each"),
    Variant("Ant", "4x1", "quadruped, 4x1 factorization (listed in the paper's table)"),
    Variant("HalfCheetah", "2x3", "planar runner, 2 agents: back leg | front leg"),
    Variant("HalfCheetah", "6x1", "planar runner, 6 agents: one joint each"),
    Variant("Hopper", "3x1", "one-legged hopper, 3 agents: thigh | leg | foot"),
    Variant("Walker2d", "2x3", "planar biped, 2 agents: right leg | left leg"),
    Variant("Swimmer", "2x1", "three-link swimmer, 2 agents: one joint each"),
    Variant("Humanoid", "9|8", "3D humanoid running, 2 agents: upper body (9) | lower body (8)"),
    Variant("HumanoidStandup", "9|8", "3D humanoid standing up, 2 agents: upper | lower body"),
    Variant("Pusher", "3p", "7-DoF pushing arm, 3 agents: shoulder | elbow | wrist"),
    Variant("Reacher", "2x1", "2-link reaching arm, 2 agents: upper | lower arm"),
    Variant("ManySegmentSwimmer", "10x2", "20-segment swimmer, 10 agents of 2 joints"),
    Variant("ManySegmentSwimmer", "5x4", "20-segment swimmer, 5 agents of 4 joints"),
    Variant("ManySegmentSwimmer", "6x1", "6-segment swimmer, 6 agents of 1 joint"),
    Variant("ManySegmentSwimmer", "1x2", "2-segment swimmer, 1 agent of 2 joints"),
    Variant("ManySegmentAnt", "2x3", "6 coupled ant segments, 2 agents of 3 segments"),
    Variant("ManySegmentAnt", "3x1", "3 coupled ant segments, 3 agents of 1 segment"),
    Variant("CoupledHalfCheetah", "1p1", "two half-cheetahs joined by a tendon, one agent each"),
)

VARIANTS: dict[str, Variant] = {v.id: v for v in _ROWS}
"""Every factorization of the paper's table by id, including those that fail here."""

BROKEN: dict[str, str] = {
    # obsk.py indexes data.ten_J[tendon][:2]; MuJoCo >= 3.x stores ten_J sparse (1-D), so
    # ten_J[0] is a scalar. Fails while building the observation spaces.
    "MA-CoupledHalfCheetah-1p1": "IndexError: invalid index to scalar variable.",
}
"""Factorizations gymnasium-robotics 1.4.2 offers that fail with MuJoCo 3.9.0: id -> the exact
``"<ExceptionType>: <message>"`` raised when the task base is built."""

UNAVAILABLE: dict[str, str] = {
    # The paper lists Ant 4x1; gymnasium-robotics 1.4.2 only knows Ant 2x4, 2x4d and 4x2.
    "MA-Ant-4x1": "Exception: UNKNOWN partitioning config: 4x1",
}
"""Factorizations of the paper's table that gymnasium-robotics 1.4.2 does not offer: id -> the exact
``"<ExceptionType>: <message>"`` raised when the task base is built."""


def working() -> dict[str, Variant]:
    """The variants that build and step with the pinned versions (the ones registered)."""
    return {k: v for k, v in VARIANTS.items() if k not in BROKEN and k not in UNAVAILABLE}


def _spec(v: Variant) -> ScenarioSpec:
    return ScenarioSpec(
        id=v.id,
        task=f"{_MODULE}:make_task",
        presets=f"{_MODULE}:presets",
        task_kwargs={"scenario": v.scenario, "agent_conf": v.agent_conf},
        family=FAMILY,
        description=v.description,
        extra="mamujoco",
        requires=("gymnasium_robotics",),
    )


def register_all() -> list[str]:
    """Register every working MaMuJoCo variant; return their ids.

    Idempotent: an id already registered with the same spec is skipped, so calling it again
    (from a test, or after `advgame.scenarios` did) is harmless; a *different* scenario under
    one of these ids is an error.
    """
    known = set(list_scenarios())
    ids = []
    for v in working().values():
        spec = _spec(v)
        if v.id in known:
            if scenario_spec(v.id) != spec:
                raise ConfigError(
                    f"Scenario {v.id!r} is already registered as {scenario_spec(v.id)!r}, "
                    f"not as the MaMuJoCo variant {spec!r}; rename one of them."
                )
        else:
            register(spec)
        ids.append(v.id)
    return ids
