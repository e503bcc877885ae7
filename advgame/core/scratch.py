"""A running job's scratch folder: where a long job keeps checkpoints that outlive an interruption.

`advgame.runner.run.run_units` keeps a part file per finished unit; a unit that is killed half
way (a session ends, a user presses Ctrl-C) had nothing to show and started again from zero. A
runner that keeps part files now also gives each unit a folder beside them, named after the
unit's key, which it removes once the unit's part file is written: a unit that runs again after
an interruption finds there what it saved. The runner lives above the jobs (`advgame.training`
builds them), so the folder is passed down through this module rather than imported from the
runner.

Example:
    >>> import tempfile
    >>> from pathlib import Path
    >>> scratch() is None
    True
    >>> with scratch_folder(Path(tempfile.gettempdir()) / "unit.scratch"):
    ...     scratch().name
    'unit.scratch'
    >>> scratch() is None
    True

"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["scratch", "scratch_folder"]

_CURRENT: list[Path] = []


def scratch() -> Path | None:
    """The running unit's scratch folder (it may not exist yet), or None where it has none.

    None: the unit keeps no part files (nothing would find what it saved), or it runs on Ray,
    whose workers need not share the driver's disk.
    """
    return _CURRENT[-1] if _CURRENT else None


@contextmanager
def scratch_folder(path: Path | None) -> Iterator[None]:
    """Make `path` the scratch folder of the code run inside (None: no folder)."""
    if path is None:
        yield
        return
    _CURRENT.append(Path(path))
    try:
        yield
    finally:
        _CURRENT.pop()
