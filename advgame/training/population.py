"""Populations of policies: checkpointed protagonists and adversaries with metadata, on disk.

A member is any policy *spec* (an SB3 checkpoint, a noise or schedule adversary, ...) plus
who it plays and where it came from. Specs are stored as ``{"type": "module:Class",
"fields": {...}}`` so a population file can be read back in any process (and by hand).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from advgame.core.config import write_atomic
from advgame.core.files import read_json, reading
from advgame.core.registry import load
from advgame.errors import ConfigError

__all__ = [
    "PATH_FIELDS",
    "SAMPLING",
    "ZERO",
    "Member",
    "Population",
    "spec_from_dict",
    "spec_to_dict",
]

SAMPLING = ("latest", "uniform", "fictitious")
PATH_FIELDS = ("path", "normalizer")
ZERO = "advgame.adversaries.noise:ZeroAdversary"
"""The no-op adversary, by name (the user folders build on the core, never the other way)."""
"""Spec fields holding files; stored relative to the population file when inside its folder."""


def spec_to_dict(spec: Any) -> dict[str, Any]:
    """A dataclass policy spec as a JSON-friendly dict."""
    if not dataclasses.is_dataclass(spec) or isinstance(spec, type):
        raise ConfigError(
            f"Only dataclass policy specs can be stored in a population, got {spec!r}."
        )
    cls = type(spec)
    return {"type": f"{cls.__module__}:{cls.__qualname__}", "fields": dataclasses.asdict(spec)}


def spec_from_dict(data: dict[str, Any]) -> Any:
    """Rebuild a spec written by `spec_to_dict`."""
    cls = load(data["type"])
    hints = {f.name: f for f in dataclasses.fields(cls)}
    fields = {
        k: tuple(v) if isinstance(v, list) and k in hints else v for k, v in data["fields"].items()
    }
    return cls(**fields)


@dataclass(frozen=True)
class Member:
    """One policy of a population."""

    id: str
    """Unique id, e.g. ``"observation_adversary@3"``."""
    side: str
    """``"protagonist"`` or ``"adversary"``."""
    agent: str
    """The agent id it plays."""
    spec: Any
    """The policy spec (``build(info) -> Policy``)."""
    iteration: int = -1
    """Training iteration it was saved at (-1: not from training)."""
    learned: bool = True
    """Whether it is a trained snapshot (fictitious play samples only these)."""
    meta: dict[str, Any] = field(default_factory=dict)
    """Free-form metadata (scenario, seed, returns at save time)."""

    @classmethod
    def noop(cls, agent: str) -> Member:
        """Adversary `agent`'s no-op (the nominal game) as the unlearned member ``<agent>:noop``."""
        return cls(f"{agent}:noop", "adversary", agent, load(ZERO)(), 0, learned=False)

    def opponent_spec(self) -> Any:
        """The spec as an opponent inside training games plays it: sampling, not deterministic.

        Frozen opponents act stochastically during training (the alternation loop and PSRO's
        best responses); specs without a ``deterministic`` field are returned as they are.
        """
        spec = self.spec
        return (
            dataclasses.replace(spec, deterministic=False)
            if hasattr(spec, "deterministic")
            else spec
        )

    def to_dict(self, base: Path | None = None) -> dict[str, Any]:
        """JSON form; file paths under `base` are stored relative to it (a run can move)."""
        spec = spec_to_dict(self.spec)
        if base is not None:
            fields = spec["fields"]
            spec["fields"] = {
                k: _relative(v, base) if k in PATH_FIELDS else v for k, v in fields.items()
            }
        return {
            "id": self.id,
            "side": self.side,
            "agent": self.agent,
            "iteration": self.iteration,
            "learned": self.learned,
            "meta": self.meta,
            "spec": spec,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], base: Path | None = None) -> Member:
        """Inverse of `to_dict`: relative file paths are resolved against `base`."""
        spec = dict(data["spec"])
        if base is not None:
            fields = spec["fields"]
            spec["fields"] = {
                k: _absolute(v, base) if k in PATH_FIELDS else v for k, v in fields.items()
            }
        return cls(
            data["id"],
            data["side"],
            data["agent"],
            spec_from_dict(spec),
            data.get("iteration", -1),
            data.get("learned", True),
            data.get("meta", {}),
        )


def _relative(value: Any, base: Path) -> Any:
    if not isinstance(value, str):
        return value
    try:
        return Path(value).resolve().relative_to(base.resolve()).as_posix()
    except ValueError:  # outside the population's folder: keep it as given
        return value


def _absolute(value: Any, base: Path) -> Any:
    if not isinstance(value, str) or Path(value).is_absolute():
        return value
    return str(base.resolve() / value)


class Population:
    """An ordered collection of members, saved as one JSON file.

    Example:
        >>> from advgame.adversaries import ZeroAdversary
        >>> pop = Population()
        >>> pop.add(Member("zero", "adversary", "observation_adversary", ZeroAdversary(), learned=False))
        >>> [m.id for m in pop.of("observation_adversary")]
        ['zero']

    """

    def __init__(self, members: list[Member] | None = None) -> None:
        self.members: list[Member] = list(members or [])

    def __iter__(self) -> Iterator[Member]:
        return iter(self.members)

    def __len__(self) -> int:
        return len(self.members)

    def add(self, member: Member) -> None:
        """Append a member (ids must be unique)."""
        if any(m.id == member.id for m in self.members):
            raise ConfigError(f"The population already has a member {member.id!r}.")
        self.members.append(member)

    def drop_missing(self) -> None:
        """Keep only the members whose model file remains.

        A run compacted or parked to its last checkpoints keeps the members those hold.
        """
        self.members = [m for m in self.members if _file_remains(m.spec)]

    def of(self, agent: str, learned_only: bool = False) -> list[Member]:
        """Members playing `agent`, oldest first."""
        return [m for m in self.members if m.agent == agent and (m.learned or not learned_only)]

    def sample(self, agent: str, how: str, rng: np.random.Generator) -> Member:
        """Draw an opponent for `agent` from its members.

        ``latest``: the newest member; ``uniform``: any member; ``fictitious``: fictitious play,
        uniform over trained snapshots only.
        """
        if how not in SAMPLING:
            raise ConfigError(f"sampling must be one of {SAMPLING}, got {how!r}.")
        pool = self.of(agent, learned_only=how == "fictitious") or self.of(agent)
        if not pool:
            raise ConfigError(f"The population has no member for {agent!r}.")
        if how == "latest":
            return pool[-1]
        return pool[int(rng.integers(len(pool)))]

    def save(self, path: str | Path) -> None:
        """Write atomically (a crash leaves the old file or the new one, never half of one)."""
        base = Path(path).parent
        write_atomic(path, json.dumps([m.to_dict(base) for m in self.members], indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> Population:
        """Read a population file."""
        fix = (
            f"It is rewritten by the run that owns it: resume or rerun that run, or delete "
            f"{Path(path).parent} and train again."
        )
        data = read_json(path, "population file", fix, kind=list)
        base = Path(path).parent
        with reading(path, "population file", fix):
            return cls([Member.from_dict(d, base) for d in data])


def _file_remains(spec: Any) -> bool:
    """Whether `spec`'s model file (its ``path``, if it has one) exists."""
    path = getattr(spec, "path", None)
    return not path or Path(path).exists()
