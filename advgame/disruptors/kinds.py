"""Disruptor kinds by name, and specs from plain dicts (as JSON configs and the CLI give them)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from advgame.core.config import from_dict
from advgame.core.disruptor import DisruptorSpec
from advgame.core.schedule import Schedule
from advgame.disruptors.action import ActionDisruptor
from advgame.disruptors.arm import ArmDisruptor
from advgame.disruptors.dynamics import DynamicsDisruptor, Param
from advgame.disruptors.force import ForceDisruptor
from advgame.disruptors.observation import ObservationDisruptor
from advgame.disruptors.reward import RewardDisruptor
from advgame.disruptors.workspace import Shift, WorkspaceDisruptor
from advgame.errors import ConfigError, UnknownNameError, did_you_mean

__all__ = ["KINDS", "from_config"]

KINDS: dict[str, type[DisruptorSpec]] = {
    "observation": ObservationDisruptor,
    "action": ActionDisruptor,
    "reward": RewardDisruptor,
    "dynamics": DynamicsDisruptor,
    "force": ForceDisruptor,
    "workspace": WorkspaceDisruptor,
    "arm": ArmDisruptor,
}
"""Disruptor kinds by name."""


def from_config(kind: str, config: Mapping[str, Any] | DisruptorSpec) -> DisruptorSpec:
    """Build a spec from a kind name and a plain dict (as found in JSON/CLI configs).

    ``schedule`` may be a dict of `Schedule` fields; dynamics ``params`` may be dicts of
    `Param` fields. ``kind="cost"`` is the reward disruptor with ``signal="cost"``.

    Example:
        >>> from_config("observation", {"eps": 0.1, "schedule": {"every": 100}}).schedule.every
        100

    """
    if isinstance(config, DisruptorSpec):
        return config
    if not isinstance(kind, str) or kind not in [*KINDS, "cost"]:
        raise UnknownNameError(
            f"Unknown disruptor kind {kind!r}.{did_you_mean(str(kind), KINDS)} Known kinds: "
            f"{sorted([*KINDS, 'cost'])}."
        )
    if not isinstance(config, Mapping):
        raise ConfigError(
            f"The options of a {kind!r} disruptor must be a dict (e.g. {{}} for the defaults, "
            f'{{"schedule": {{"every": 10}}}}), or a list of dicts for several, got {config!r}.'
        )
    cfg = dict(config)
    if kind == "cost":
        kind, cfg = "reward", {**cfg, "signal": "cost"}
    if isinstance(cfg.get("schedule"), Mapping):
        cfg["schedule"] = from_dict(Schedule, cfg["schedule"])
    if kind == "dynamics" and _is_list(cfg.get("params")):
        cfg["params"] = tuple(_nested(Param, p) for p in cfg["params"])
    if kind == "workspace" and _is_list(cfg.get("shifts")):
        cfg["shifts"] = tuple(_nested(Shift, s) for s in cfg["shifts"])
    return from_dict(KINDS[kind], cfg)


def _is_list(value: Any) -> bool:
    return isinstance(value, (list, tuple))


def _nested(cls: type[Any], value: Any) -> Any:
    """A `Param` or `Shift` given as itself or as a dict of its fields."""
    return value if isinstance(value, cls) else from_dict(cls, value)
