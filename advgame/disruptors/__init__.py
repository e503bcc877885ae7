"""Disruptors: what an adversary may perturb, each one hook plus a budget.

The registry maps a kind name (as used in dict configs and on the command line) to its spec
class; a new disruptor is one file plus one line here.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from advgame.core.schedule import Schedule
from advgame.disruptors.action import ActionDisruptor
from advgame.disruptors.arm import ArmDisruptor
from advgame.disruptors.base import Disruptor, DisruptorSpec
from advgame.disruptors.dynamics import DynamicsDisruptor, Param
from advgame.disruptors.force import ForceDisruptor
from advgame.disruptors.observation import ObservationDisruptor
from advgame.disruptors.reward import RewardDisruptor
from advgame.disruptors.workspace import Shift, WorkspaceDisruptor
from advgame.errors import AdvgameError, ConfigError, UnknownNameError, did_you_mean

__all__ = [
    "KINDS",
    "ActionDisruptor",
    "ArmDisruptor",
    "Disruptor",
    "DisruptorSpec",
    "DynamicsDisruptor",
    "ForceDisruptor",
    "ObservationDisruptor",
    "Param",
    "RewardDisruptor",
    "Shift",
    "WorkspaceDisruptor",
    "from_config",
]

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
            f"The options of a {kind!r} disruptor must be a dict of its fields (e.g. "
            f"{{'eps': 0.1}}; {{}} for its defaults), got {config!r}."
        )
    try:
        return _build(kind, dict(config))
    except AdvgameError as exc:
        raise type(exc)(f"In the {kind!r} disruptor {dict(config)!r}: {exc}") from None
    except (TypeError, ValueError, KeyError, IndexError, AttributeError) as exc:
        raise ConfigError(
            f"Bad options for a {kind!r} disruptor {dict(config)!r}: {exc}. Its fields are "
            f"those of {KINDS['reward' if kind == 'cost' else kind].__name__} "
            "(see its docstring)."
        ) from exc


def _build(kind: str, cfg: dict[str, Any]) -> DisruptorSpec:
    """`from_config`'s construction, nested dicts (schedule, params, shifts) included."""
    if kind == "cost":
        kind, cfg = "reward", {**cfg, "signal": "cost"}
    if isinstance(cfg.get("schedule"), Mapping):
        cfg["schedule"] = _item(Schedule, cfg["schedule"], "schedule")
    if kind == "dynamics" and "params" in cfg:
        cfg["params"] = tuple(_item(Param, p, "params") for p in cfg["params"])
    if kind == "workspace" and "shifts" in cfg:
        cfg["shifts"] = tuple(_item(Shift, s, "shifts") for s in cfg["shifts"])
    return KINDS[kind](**cfg)


def _item(cls: type, value: Any, field: str) -> Any:
    """One entry of a list field: an instance of `cls` or a dict of its fields."""
    if isinstance(value, cls):
        return value
    if not isinstance(value, Mapping):
        raise ConfigError(
            f"Each of {field} must be a {cls.__name__} or a dict of its fields, got {value!r}."
        )
    names = [f.name for f in dataclasses.fields(cls)] if dataclasses.is_dataclass(cls) else []
    unknown = [k for k in value if names and k not in names]
    if unknown:
        raise UnknownNameError(
            f"{field} has no field {unknown[0]!r}.{did_you_mean(str(unknown[0]), names)} "
            f"{cls.__name__} fields: {names}."
        )
    return cls(**value)
