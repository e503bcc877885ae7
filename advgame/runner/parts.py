"""Part files: the name of a unit's file of results, and reading it back from any folder.

A finished unit's record (`advgame.runner.units.UnitRecord`) is kept in ``<parts>/<key>.pkl``.
`unit_key` names a unit by its values; `part_key` does so with the files its specs name written
relative to the part files' folder, so a table or a search is read back whatever folder the
command runs from and wherever the folder was moved or cloned. `read_unit_part` also finds,
and renames, a part file named by `unit_key` before `part_key` existed.
"""

from __future__ import annotations

import copy
import os
from pathlib import Path
from typing import Any

from advgame.core.moved import stable_pickle
from advgame.runner.units import UnitRecord, digest, pickled, read_part, walk_files

__all__ = ["has_part", "part_key", "read_unit_part", "unit_key"]


def unit_key(unit: Any) -> str:
    """The name of a unit's part file: the digest of its pickle written without a memo.

    A plain pickle refers back to an object it has already written, so two equal units differ
    when one shares a string between fields and the other holds two equal copies (a spec built
    in this process vs. one read back from JSON): a resumed run would then miss its finished
    part files and redo them. Without the memo the pickle depends on the values alone, and
    `advgame.core.moved.stable_pickle` writes every class under its name before any module
    moved, so reorganising the code renames no part file.
    """
    try:
        return digest(stable_pickle(unit))
    except Exception:
        pickled(unit)  # a unit that cannot be pickled: a ConfigError saying what to change
        raise


def part_key(unit: Any, parts: Path | None) -> str:
    """The name of `unit`'s part file in folder `parts`: `unit_key` with its files rebased.

    Every existing file the unit's specs name (`PATH_FIELDS`) is written relative to `parts`
    before the digest, so the key holds wherever the command runs from and wherever the folder
    lies: ``advgame campaign zoo/x.toml`` from the repository's root and ``advgame campaign
    x.toml`` from ``zoo/`` name the same part files, and so does a clone elsewhere. Paths that
    name no file are left as they are. Without `parts`, `unit_key`.
    """
    if parts is None:
        return unit_key(unit)
    base = os.path.abspath(parts)

    def rebase(_: str, value: Any) -> Any:
        if not isinstance(value, (str, Path)) or not os.path.exists(value):
            return value
        try:
            return Path(os.path.relpath(os.path.abspath(value), base)).as_posix()
        except ValueError:  # another drive (Windows): no relative path
            return Path(os.path.abspath(value)).as_posix()

    return unit_key(walk_files(unit, rebase, _with_fields))


def _with_fields(obj: Any, **changes: Any) -> Any:
    """A copy of dataclass `obj` with `changes`, its checks not run again.

    A rebased path is relative to the part files, not to the current folder, so a spec that
    checks its file exists (`adversaries.llm_backends.LocalModel`) would refuse it.
    """
    new = copy.copy(obj)
    for name, value in changes.items():
        object.__setattr__(new, name, value)
    return new


def read_unit_part(parts: Path | None, unit: Any, key: str | None = None) -> UnitRecord | None:
    """`unit`'s record in `parts` (`part_key`, or `key` if given), None if it has none.

    A part file written before `part_key` (named by `unit_key`, whose paths were as the
    command gave them) is renamed to the new name when found, so a folder of older part files
    is read back once from where it was written and from anywhere after that.
    """
    if parts is None:
        return None
    key = part_key(unit, parts) if key is None else key
    rec = read_part(parts, key)
    if rec is not None:
        return rec
    old = unit_key(unit)
    if old == key or not (parts / f"{old}.pkl").exists():
        return None
    os.replace(parts / f"{old}.pkl", parts / f"{key}.pkl")
    rec = read_part(parts, key)
    if rec is not None:
        rec.key = key
    return rec


def has_part(parts: Path, unit: Any) -> bool:
    """Whether `unit` has a part file in `parts`, under `part_key` or the older `unit_key`."""
    return any((parts / f"{k}.pkl").is_file() for k in (part_key(unit, parts), unit_key(unit)))
