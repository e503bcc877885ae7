"""Learned adversaries read back from runs and population files, for the table's columns.

`snapshots` lists a run's (or file's) learned adversary members by iteration with the preset
they trained in; `misfit` says why such adversaries cannot act in a threat model (other agents
or action shapes). `advgame.evaluation.table.columns` builds the ``learned`` and ``population``
columns from them.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from advgame.errors import ConfigError

__all__ = ["adversary_shapes", "misfit", "preset_of", "snapshots"]


@functools.lru_cache(maxsize=32)
def adversary_shapes(scenario: str, preset: str) -> dict[str, tuple[int, ...]]:
    """Each adversary's action shape in `preset` of `scenario` (one game built per pair)."""
    from advgame.core.registry import make

    game = make(scenario, preset=preset)
    shapes = {a: tuple(game.action_space(a).shape or ()) for a in game.adversaries}
    game.close()
    return shapes


def misfit(scenario: str, preset: str, specs: Mapping[str, Any]) -> str:
    """Why `specs` cannot act in `preset` of `scenario` ('' if they can)."""
    from advgame.agents.common.checkpoint import SB3Checkpoint, load_model

    shapes = adversary_shapes(scenario, preset)
    for agent, spec in specs.items():
        if agent not in shapes:
            return (
                f"A learned adversary plays {agent!r}, but the threat model {preset!r} of "
                f"{scenario} has no such agent (it has {sorted(shapes)})"
            )
        if isinstance(spec, SB3Checkpoint):
            have = tuple(load_model(str(spec.path), spec.algo).action_space.shape or ())
            if have != shapes[agent]:
                return (
                    f"The learned {agent!r} acts with shape {have}, but in the threat model "
                    f"{preset!r} of {scenario} it has {shapes[agent]}"
                )
    return ""


def snapshots(source: Path, opts: Mapping[str, str]) -> tuple[str, dict[int, dict[str, Any]]]:
    """The preset and ``{iteration: {agent: learned adversary member}}`` of a run or file."""
    from advgame.training.population import Population

    file = source if source.suffix == ".json" else source / "population.json"
    if not file.is_file():
        raise ConfigError(
            f"{source} has no population.json; give a run directory written by `advgame "
            "train` or a population file."
        )
    snaps: dict[int, dict[str, Any]] = {}
    for m in Population.load(file):
        if m.side == "adversary" and m.learned:
            snaps.setdefault(m.iteration, {})[m.agent] = m
    return preset_of(file, opts), snaps


def preset_of(file: Path, opts: Mapping[str, str]) -> str:
    """The preset a population file's adversaries trained in: ``preset=`` or its run's config."""
    if "preset" in opts:
        return opts["preset"]
    config = file.parent / "config.json"
    if not config.is_file():
        raise ConfigError(
            f"{file} is not in a run directory (no config.json beside it), so its preset is "
            f"unknown; add it to the spec, e.g. population:{file},preset=atla."
        )
    import json

    return str(json.loads(config.read_text()).get("preset", "default"))
