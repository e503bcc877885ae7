"""Where jobs run: a local process pool or Ray core, through one code path.

`run_units(fn, units, ...)` calls the module-level function ``fn`` on every picklable unit and
returns one `UnitRecord` per unit, in order. Evaluation (`advgame.evaluation.evaluate`, one unit
per cell and seed) and population training (`advgame.psro`, one unit per best
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

import dataclasses
import hashlib
import logging
import os
import pickle
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from advgame.core.config import write_atomic
from advgame.core.files import reading
from advgame.errors import AdvgameError, ConfigError, FileFormatError
from advgame.training.population import PATH_FIELDS

__all__ = [
    "EXECUTORS",
    "JobFailedError",
    "UnitRecord",
    "close_pool",
    "digest",
    "first_action",
    "run_units",
    "ship",
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


@dataclass
class UnitRecord:
    """What running one unit gave: its value and how it ran."""

    key: str
    """A digest of the unit (names its part file)."""
    value: Any = None
    """What ``fn(unit)`` returned (None if it failed)."""
    error: str | None = None
    """The last error, if every attempt failed."""
    attempts: int = 0
    """Attempts made in this call (0: read back from a part file)."""
    pid: int = 0
    """The worker process that ran it."""
    host: str = ""
    """The worker's host name."""
    start: float = 0.0
    """Worker wall clock (``time.time()``) when the unit started."""
    end: float = 0.0
    """Worker wall clock when it ended."""
    startup_s: float | None = None
    """Seconds from the unit's start to its first action (None if nothing acted)."""
    extra: dict[str, Any] = field(default_factory=dict)
    """Driver-side timing: ``submitted`` and ``received`` (``time.time()``)."""

    def timing(self) -> dict[str, Any]:
        """The record without its value (one line of ``jobs.jsonl``)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if k != "value"}


def _name(unit: Any) -> str:
    for attrs in (("protagonist", "adversary", "seeds"), ("name",)):
        if all(hasattr(unit, a) for a in attrs):
            return " ".join(f"{a}={getattr(unit, a)!r}" for a in attrs)
    return type(unit).__name__


def digest(blob: bytes) -> str:
    """A stable name of a pickled unit: the SHA-256 of its pickle (24 hex digits)."""
    return hashlib.sha256(blob).hexdigest()[:24]


# -- instrumenting the first action ---------------------------------------------------------
_FIRST: list[float] = []


def first_action() -> None:
    """Mark the first action of the running unit (later calls in the same unit are ignored)."""
    if not _FIRST:
        _FIRST.append(time.time())


# -- files travelling with units ------------------------------------------------------------
def _walk(obj: Any, visit: Callable[[str, Any], Any]) -> Any:
    """Rebuild `obj` with every file-naming dataclass field (`PATH_FIELDS`) through `visit`."""
    if isinstance(obj, dict):
        return {k: _walk(v, visit) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_walk(v, visit) for v in obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        changes = {}
        for f in dataclasses.fields(obj):
            if not f.init:
                continue
            old = getattr(obj, f.name)
            new = visit(f.name, old) if f.name in PATH_FIELDS else _walk(old, visit)
            if new is not old:
                changes[f.name] = new
        return dataclasses.replace(obj, **changes) if changes else obj
    return obj


def ship(unit: Any) -> dict[str, bytes]:
    """Return ``{path: bytes}`` of every existing file the unit's specs name."""
    files: dict[str, bytes] = {}

    def grab(_: str, value: Any) -> Any:
        if isinstance(value, str) and os.path.isfile(value):
            files[value] = Path(value).read_bytes()
        return value

    _walk(unit, grab)
    return files


def _materialize(unit: Any, files: dict[str, bytes]) -> Any:
    """Write shipped files to this node's cache (by content digest); point the unit at them."""
    if not files:
        return unit
    root = Path(tempfile.gettempdir()) / "advgame-shipped"
    local = {}
    for path, blob in files.items():
        target = root / digest(blob) / Path(path).name
        if not target.exists():  # same content, same file: loaded models stay cached
            target.parent.mkdir(parents=True, exist_ok=True)
            write_atomic(target, blob)
        local[path] = str(target)
    return _walk(unit, lambda _, v: local.get(v, v) if isinstance(v, str) else v)


# -- what a worker runs ---------------------------------------------------------------------
def _init_worker(path: list[str]) -> None:
    """Worker initializer: the caller's import path; one thread for torch and BLAS."""
    sys.path[:] = path
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"  # read by torch and BLAS when (and if) a job imports them
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def _loads(blob: bytes) -> Any:
    try:
        return pickle.loads(blob)
    except Exception as exc:  # e.g. a callable whose module a fresh process cannot import
        raise ConfigError(
            f"A worker process cannot load a job: {type(exc).__name__}: {exc}. Define callables "
            "and specs at module level of an importable module, or use workers=1."
        ) from None


def pickled(obj: Any) -> bytes:
    """`obj` pickled for a worker; a `ConfigError` saying what to change if it cannot be."""
    try:
        return pickle.dumps(obj)
    except Exception as exc:
        raise ConfigError(
            f"Job {_name(obj)} cannot go to a worker process ({type(exc).__name__}: {exc}). "
            "Use module-level functions, not lambdas or closures, and specs rather than live "
            "policies; or use workers=1."
        ) from None


_MTIMES: dict[str, int] = {}


def _forget_rewritten(unit: Any) -> None:
    """Drop this worker's cached models if a checkpoint the unit names changed on disk.

    Warm workers keep loaded models (`advgame.training.checkpoint.load_model`, cached by path)
    across units and calls; a file rewritten at the same path must not be served stale.
    """
    changed = False

    def look(_: str, value: Any) -> Any:
        nonlocal changed
        if isinstance(value, str) and os.path.isfile(value):
            mtime = os.stat(value).st_mtime_ns
            changed |= _MTIMES.setdefault(value, mtime) != mtime
            _MTIMES[value] = mtime
        return value

    _walk(unit, look)
    checkpoint = sys.modules.get("advgame.training.checkpoint")
    if changed and checkpoint is not None:
        log.info("a checkpoint changed on disk: reloading models in worker %d", os.getpid())
        checkpoint.load_model.cache_clear()


def timed(fn: Callable[[Any], Any], unit: Any, start: float | None = None) -> dict[str, Any]:
    """``fn(unit)``'s value and timing (`UnitRecord` fields), from `start` (default: now)."""
    start = time.time() if start is None else start
    _FIRST.clear()
    value = fn(unit)
    end = time.time()
    startup = _FIRST[0] - start if _FIRST else None
    return {"value": value, "startup_s": startup, "pid": os.getpid(), "start": start, "end": end}


def execute(fn_blob: bytes, unit_blob: bytes, files: dict[str, bytes]) -> dict[str, Any]:
    """Run one unit in a worker; return its value and timing (`UnitRecord` fields).

    The clock starts before the unit is unpickled and its files written: start-up included.
    """
    import socket

    start = time.time()
    fn, unit = _loads(fn_blob), _materialize(_loads(unit_blob), files)
    _forget_rewritten(unit)
    return {**timed(fn, unit, start), "host": socket.gethostname()}


def close_pool() -> None:
    """Stop the local pool's warm workers now (otherwise they live until this process exits)."""
    from advgame.evaluation import _local

    _local.shutdown()


def write_timings(records: Sequence[UnitRecord], path: str | Path) -> None:
    """Write one JSON line of timing per record (`UnitRecord.timing`) to `path`."""
    import json

    lines = [json.dumps(r.timing(), default=str) for r in records]
    Path(path).write_text("".join(line + "\n" for line in lines))


# -- persistence ----------------------------------------------------------------------------
def _read_part(parts: Path | None, key: str) -> UnitRecord | None:
    if parts is None or not (parts / f"{key}.pkl").exists():
        return None
    path = parts / f"{key}.pkl"
    fix = f"Delete {path}: its unit is then run again."
    with reading(path, "finished-unit part file", fix), path.open("rb") as f:
        rec: UnitRecord = pickle.load(f)
    if not isinstance(rec, UnitRecord):
        raise FileFormatError(
            f"The part file {path} holds a {type(rec).__name__}, not a unit record. {fix}",
            path=str(path),
        )
    rec.attempts = 0
    return rec


def _write_part(parts: Path | None, rec: UnitRecord) -> None:
    if parts is None:
        return
    write_atomic(parts / f"{rec.key}.pkl", pickle.dumps(rec))  # a kill: whole or absent


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
        progress: an object with ``update()`` (a tqdm bar), called once per finished unit.

    """
    _check(executor, workers, max_retries, start_method)
    parts = Path(parts_dir) if parts_dir is not None else None
    if parts is not None:
        parts.mkdir(parents=True, exist_ok=True)
    needs_pickle = parts is not None or executor != "local" or (workers > 1 and len(units) > 1)
    keys = [digest(pickled(u)) if needs_pickle else f"unit-{i}" for i, u in enumerate(units)]
    records: list[UnitRecord | None] = [_read_part(parts, k) for k in keys]
    todo = [i for i, r in enumerate(records) if r is None]
    if len(todo) < len(units):
        log.info("%d of %d jobs already done in %s", len(units) - len(todo), len(units), parts)
    for _ in range(len(units) - len(todo)):
        progress is not None and progress.update()
    ship_files = executor == "ray" if ship_files is None else ship_files
    from advgame.evaluation import _local, _ray

    run = {"local": _local.run_local, "ray": _ray.run_ray}[executor]
    fresh = run(fn, [units[i] for i in todo], [keys[i] for i in todo], Options(
        workers, address, max_retries, parts, ship_files, start_method, progress))  # fmt: skip
    for i, rec in zip(todo, fresh, strict=True):
        records[i] = rec
    failed = [(units[i], r.error) for i, r in enumerate(records) if r is not None and r.error]
    if failed:
        raise JobFailedError([(u, str(e)) for u, e in failed], len(units) - len(failed))
    return [r for r in records if r is not None]


@dataclass(frozen=True)
class Options:
    """How `run_units` runs its units (its arguments, for the back ends)."""

    workers: int
    address: str | None
    max_retries: int
    parts: Path | None
    ship_files: bool
    start_method: str
    progress: Any


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


def finish(rec: UnitRecord, out: dict[str, Any], opts: Options) -> UnitRecord:
    """Fill `rec` from a worker's answer (no error left), persist it, tick the bar."""
    rec.error = None
    for name, value in out.items():
        setattr(rec, name, value)
    rec.extra["received"] = time.time()
    _write_part(opts.parts, rec)
    if opts.progress is not None:
        opts.progress.update()
    return rec


def retry(rec: UnitRecord, error: str, opts: Options) -> bool:
    """Record a failed attempt; return whether the unit gets another one."""
    rec.error = error
    again = rec.attempts <= opts.max_retries
    log.warning("job %s attempt %d failed: %s%s", rec.key, rec.attempts, error,
                "; retrying" if again else "; giving up")  # fmt: skip
    return again
