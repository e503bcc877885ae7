"""Where jobs run: a local process pool or Ray core, through one code path.

`run_units(fn, units, ...)` calls the module-level function ``fn`` on every picklable unit and
returns one `UnitRecord` per unit, in order. Evaluation (`advgame.evaluation.evaluate`, one unit
per cell and seed) and population training (`advgame.workflows.psro`, one unit per best
response) both go through it. The executor is chosen by name:

- ``"local"`` (the default): this process for ``workers=1``, else a `ProcessPoolExecutor`
  whose workers live for the whole call (warm: loaded checkpoints stay cached in them);
- ``"ray"``: Ray core tasks on a local Ray (started with ``workers`` CPUs) or on the cluster at
  ``address``; Ray reuses its worker processes across tasks, so they are warm too.

What every executor guarantees:

- **bounded retries**: a unit whose worker dies (killed, out of memory) or that raises a
  non-advgame exception is run again, at most ``max_retries`` more times; one that still fails
  is listed in a `JobFailedError` raised after every other unit has finished. An `AdvgameError`
  raised by a unit (the user's mistake) is raised at once, as in a plain call.
- **no recomputation**: with ``parts_dir``, every finished unit is written there as one part
  file (named by a digest of the unit) the moment it finishes; a restarted call reads the parts
  back instead of running their units again.
- **files travel**: with ``ship_files`` (the default on Ray) the files a unit's policy specs
  name (``path``/``normalizer`` fields, e.g. `SB3Checkpoint`) go to the workers as bytes in
  Ray's object store and are written to a per-node cache, so a multi-node cluster needs no
  shared file system. ``ship_files=False`` passes paths as they are (a shared file system).
- **warm workers**: the local pool lives on across calls and Ray reuses its workers, so a
  loaded checkpoint serves later units; a checkpoint rewritten at the same path is reloaded.
- **instrumented**: each record holds the worker's pid, start and end times, attempts, and
  ``startup_s``: the time from the unit's start to its protagonist's first action
  (`first_action` marks it), the per-job start-up cost.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from advgame.core.progress import count_before
from advgame.errors import AdvgameError, ConfigError
from advgame.runner.parts import part_key, read_unit_part, unit_key
from advgame.runner.units import (
    Options,
    UnitRecord,
    _name,
    digest,
    drop_scratch,
    first_action,
    ship,
)

__all__ = [
    "EXECUTORS",
    "JobFailedError",
    "UnitRecord",
    "close_pool",
    "digest",
    "first_action",
    "run_units",
    "ship",
    "unit_key",
    "write_timings",
]

log = logging.getLogger(__name__)

EXECUTORS = ("local", "ray")
"""Executor names accepted by `run_units` and `advgame.evaluation.evaluate`."""


class JobFailedError(AdvgameError, RuntimeError):
    """Some units failed on every attempt; ``failures`` lists ``(unit, error)`` pairs."""

    def __init__(self, failures: list[tuple[Any, str]], done: int) -> None:
        self.failures = failures
        lines = "\n".join(f"  - {_name(u)}: {err}" for u, err in failures)
        super().__init__(
            f"{len(failures)} job(s) failed after their retries ({done} finished and kept):\n"
            f"{lines}\nFix the cause and run the same call again: finished jobs are not rerun "
            "when a parts folder is given."
        )


def close_pool() -> None:
    """Stop the local pool's warm workers now (otherwise they live until this process exits)."""
    from advgame.runner import local as _local

    _local.shutdown()


def write_timings(records: Sequence[UnitRecord], path: str | Path) -> None:
    """Write one JSON line of timing per record (`UnitRecord.timing`) to `path`."""
    import json

    lines = [json.dumps(r.timing(), default=str) for r in records]
    Path(path).write_text("".join(line + "\n" for line in lines))


# -- persistence ----------------------------------------------------------------------------
def run_units(
    fn: Callable[[Any], Any],
    units: Sequence[Any],
    *,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    max_retries: int = 2,
    parts_dir: str | Path | None = None,
    ship_files: bool | None = None,
    start_method: str = "forkserver",
    progress: Any = None,
    scratch: bool = False,
    on_unit: Callable[[int, UnitRecord], None] | None = None,
) -> list[UnitRecord]:
    """Run ``fn(unit)`` for every unit on `executor`; return one `UnitRecord` per unit, in order.

    Args:
        fn: a module-level function (it is pickled by reference).
        units: picklable values.
        executor: ``"local"`` or ``"ray"``.
        workers: local: worker processes (1 runs here); Ray: units in flight at once, and the
            CPUs of the local Ray it starts when none is running and `address` is None.
        address: Ray only: the cluster (``"auto"``, ``"ray://head:10001"``); None attaches to
            a Ray already initialized in this process or starts a local one.
        max_retries: extra attempts of a unit whose worker died or that raised a non-advgame
            exception.
        parts_dir: a folder holding one part file per finished unit (created if missing).
        ship_files: send the files the specs name as bytes (default: True on Ray, False
            locally).
        start_method: local pool: ``"forkserver"`` or ``"spawn"``.
        progress: an object with ``update()`` (a tqdm bar), called once per finished unit
            (units read back from part files first); or one with ``unit_done(index,
            before)``, called instead with the unit's index in `units` and whether it was
            read back (for progress weighted by unit, such as the optimal attack's
            candidates of different lengths), and ``units_started(count)`` if it has one,
            once the read-back units are counted and `count` units start.
        scratch: give each unit ``<parts_dir>/<key>.scratch/`` (`advgame.core.scratch`: the
            local executor only), which outlives an interruption and goes once the unit's part
            file is written: a unit that saves its progress there goes on from its last save
            when run again, instead of from the start. Such a unit's result then depends on
            where it was interrupted (its episodes restart at the save), so this is for long
            units where that is the lesser cost (the optimal attack's candidates), not for
            runs that promise the result of an uninterrupted run (PSRO).
        on_unit: called in this process as ``on_unit(index, record)`` for every unit: those
            read back from part files first, then each run here the moment its part file is
            written, so a caller can keep what finished units mean to it (the evaluation's
            per-job part files) before the call returns or is interrupted. Units with the
            same key are reported under one index.

    """
    _check(executor, workers, max_retries, start_method)
    parts = Path(parts_dir) if parts_dir is not None else None
    if parts is not None:
        parts.mkdir(parents=True, exist_ok=True)
    needs_pickle = parts is not None or executor != "local" or (workers > 1 and len(units) > 1)
    keys = [part_key(u, parts) if needs_pickle else f"unit-{i}" for i, u in enumerate(units)]
    records: list[UnitRecord | None] = [
        read_unit_part(parts, u, k) for u, k in zip(units, keys, strict=True)
    ]
    todo = [i for i, r in enumerate(records) if r is None]
    if len(todo) < len(units):
        log.info("%d of %d jobs already done in %s", len(units) - len(todo), len(units), parts)
    ticks = _Ticks(progress, keys, on_unit)
    for i, r in enumerate(records):
        if r is not None:
            ticks.done(keys[i], before=True, record=r)
            drop_scratch(parts, keys[i])  # a kill between its part file and the folder's removal
    ticks.started(len(todo))
    ship_files = executor == "ray" if ship_files is None else ship_files
    from advgame.runner import local as _local
    from advgame.runner import ray as _ray

    run = {"local": _local.run_local, "ray": _ray.run_ray}[executor]
    fresh = run(fn, [units[i] for i in todo], [keys[i] for i in todo], Options(
        workers, address, max_retries, parts, ship_files, start_method, ticks,
        scratch and executor == "local"))  # fmt: skip
    for i, rec in zip(todo, fresh, strict=True):
        records[i] = rec
    failed = [(units[i], r.error) for i, r in enumerate(records) if r is not None and r.error]
    if failed:
        raise JobFailedError([(u, str(e)) for u, e in failed], len(units) - len(failed))
    return [r for r in records if r is not None]


class _Ticks:
    """Tells `run_units`' progress object and `on_unit` about each finished unit."""

    def __init__(
        self,
        progress: Any,
        keys: Sequence[str],
        on_unit: Callable[[int, UnitRecord], None] | None = None,
    ) -> None:
        self.progress = progress
        self.index = {k: i for i, k in enumerate(keys)}
        self.on_unit = on_unit

    def done(self, key: str, before: bool = False, record: UnitRecord | None = None) -> None:
        """Unit `key` finished (`before`: read back from its part file) with `record`."""
        if self.on_unit is not None and record is not None:
            self.on_unit(self.index[key], record)
        if self.progress is None:
            return
        hook = getattr(self.progress, "unit_done", None)
        if hook is not None:
            hook(self.index[key], before)
        elif before:  # not part of this run's rate
            count_before(self.progress, 1)
        else:
            self.progress.update()

    def started(self, count: int) -> None:
        """`count` units start (after the read-back ones were counted)."""
        hook = getattr(self.progress, "units_started", None)
        if hook is not None:
            hook(count)


def _check(executor: str, workers: int, max_retries: int, start_method: str) -> None:
    if executor not in EXECUTORS:
        from advgame.errors import UnknownNameError, did_you_mean

        hint = did_you_mean(executor, EXECUTORS)
        raise UnknownNameError(f"Unknown executor {executor!r}.{hint} Expected one of {EXECUTORS}.")
    if type(workers) is not int or workers < 1:
        raise ConfigError(f"workers must be an int >= 1, got {workers!r}.")
    if type(max_retries) is not int or max_retries < 0:
        raise ConfigError(f"max_retries must be an int >= 0, got {max_retries!r}; e.g. 2.")
    if start_method not in ("forkserver", "spawn"):
        raise ConfigError(f"start_method must be 'forkserver' or 'spawn', got {start_method!r}.")
