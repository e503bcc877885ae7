"""What an executor runs and records, shared by its back ends (`_local`, `_ray`).

A unit travels as pickles (`pickled`), with the files its specs name as bytes (`ship`,
materialized on the worker); a worker runs it through `execute` (which times it and its first
action, `first_action`) and the driver turns the outcome into a `UnitRecord` (`finish`) or
decides on another attempt (`retry`) under the call's `Options`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import pickle
import shutil
import socket
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from advgame.core.config import write_atomic
from advgame.core.files import reading
from advgame.core.moved import load_pickle
from advgame.errors import ConfigError, FileFormatError
from advgame.training.population import PATH_FIELDS

__all__ = [
    "Options",
    "UnitRecord",
    "digest",
    "execute",
    "finish",
    "first_action",
    "init_worker",
    "pickled",
    "read_part",
    "retry",
    "ship",
    "timed",
    "walk_files",
    "write_part",
]

log = logging.getLogger(__name__)


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
def walk_files(
    obj: Any, visit: Callable[[str, Any], Any], rebuild: Callable[..., Any] = dataclasses.replace
) -> Any:
    """Rebuild `obj` with every file-naming dataclass field (`PATH_FIELDS`) through `visit`.

    A dataclass with changed fields is rebuilt by ``rebuild(obj, **changes)``: by default
    `dataclasses.replace`, which runs its checks again.
    """
    if isinstance(obj, dict):
        return {k: walk_files(v, visit, rebuild) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(walk_files(v, visit, rebuild) for v in obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        changes = {}
        for f in dataclasses.fields(obj):
            if not f.init:
                continue
            old = getattr(obj, f.name)
            new = visit(f.name, old) if f.name in PATH_FIELDS else walk_files(old, visit, rebuild)
            if new is not old:
                changes[f.name] = new
        return rebuild(obj, **changes) if changes else obj
    return obj


def ship(unit: Any) -> dict[str, bytes]:
    """Return ``{path: bytes}`` of every existing file the unit's specs name."""
    files: dict[str, bytes] = {}

    def grab(_: str, value: Any) -> Any:
        if isinstance(value, str) and os.path.isfile(value):
            files[value] = Path(value).read_bytes()
        return value

    walk_files(unit, grab)
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
    return walk_files(unit, lambda _, v: local.get(v, v) if isinstance(v, str) else v)


# -- what a worker runs ---------------------------------------------------------------------
def init_worker(path: list[str]) -> None:
    """Worker initializer: the caller's import path; one thread for torch, BLAS and MuJoCo.

    A pool already runs one worker per core, so batched simulator steps stay on the worker's
    thread unless the user set `advgame.core.physics.THREADS_VAR` themselves. Libraries' log
    lines are quieted as the command line quieted them (`advgame.core.library_logs`).
    """
    from advgame.core.library_logs import quiet_from_environment
    from advgame.core.physics import THREADS_VAR

    sys.path[:] = path
    quiet_from_environment()  # the command line's -v or not, for the envs built here
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"  # read by torch and BLAS when (and if) a job imports them
    os.environ.setdefault(THREADS_VAR, "1")
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

    Warm workers keep loaded models (`advgame.agents.common.checkpoint.load_model`, cached by path)
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

    walk_files(unit, look)
    checkpoint = sys.modules.get("advgame.agents.common.checkpoint")
    if changed and checkpoint is not None:
        log.info("a checkpoint changed on disk: reloading models in worker %d", os.getpid())
        checkpoint.load_model.cache_clear()


def timed(
    fn: Callable[[Any], Any], unit: Any, start: float | None = None, scratch: str | None = None
) -> dict[str, Any]:
    """``fn(unit)``'s value and timing (`UnitRecord` fields), from `start` (default: now).

    `scratch`: the unit's scratch folder (`advgame.core.scratch`), None for none.
    """
    from advgame.core.scratch import scratch_folder

    start = time.time() if start is None else start
    _FIRST.clear()
    with scratch_folder(Path(scratch) if scratch else None):
        value = fn(unit)
    end = time.time()
    startup = _FIRST[0] - start if _FIRST else None
    return {"value": value, "startup_s": startup, "pid": os.getpid(), "start": start, "end": end}


def execute(
    fn_blob: bytes, unit_blob: bytes, files: dict[str, bytes], scratch: str | None = None
) -> dict[str, Any]:
    """Run one unit in a worker; return its value and timing (`UnitRecord` fields).

    The clock starts before the unit is unpickled and its files written: start-up included.
    `scratch`: the unit's scratch folder (see `scratch_dir`).
    """
    start = time.time()
    fn, unit = _loads(fn_blob), _materialize(_loads(unit_blob), files)
    _forget_rewritten(unit)
    return {**timed(fn, unit, start, scratch), "host": socket.gethostname()}


def scratch_dir(opts: Options, key: str) -> str | None:
    """Unit `key`'s scratch folder, ``<parts>/<key>.scratch``, where the run asked for one.

    Only with part files (`opts.parts`) and `opts.scratch`; removed by `finish` once the unit's
    part file is written (`advgame.core.scratch`).
    """
    if opts.parts is None or not opts.scratch:
        return None
    return str(_scratch_path(opts.parts, key))


def _scratch_path(parts: Path, key: str) -> Path:
    return parts / f"{key}.scratch"


def drop_scratch(parts: Path | None, key: str) -> None:
    """Remove unit `key`'s scratch folder, if any: its part file holds the result now."""
    if parts is not None:
        shutil.rmtree(_scratch_path(parts, key), ignore_errors=True)


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
    """What a finished unit is reported to (``done(key, record=...)``; `advgame.runner.run`)."""
    scratch: bool = False
    """Give each unit a scratch folder beside its part file (`scratch_dir`)."""


def finish(rec: UnitRecord, out: dict[str, Any], opts: Options) -> UnitRecord:
    """Fill `rec` from a worker's answer (no error left), persist it, tick the bar."""
    rec.error = None
    for name, value in out.items():
        setattr(rec, name, value)
    rec.extra["received"] = time.time()
    write_part(opts.parts, rec)
    drop_scratch(opts.parts, rec.key)
    if opts.progress is not None:
        opts.progress.done(rec.key, record=rec)
    return rec


def retry(rec: UnitRecord, error: str, opts: Options) -> bool:
    """Record a failed attempt; return whether the unit gets another one."""
    rec.error = error
    again = rec.attempts <= opts.max_retries
    log.warning("job %s attempt %d failed: %s%s", rec.key, rec.attempts, error,
                "; retrying" if again else "; giving up")  # fmt: skip
    return again


def read_part(parts: Path | None, key: str) -> UnitRecord | None:
    """The record in ``<parts>/<key>.pkl`` (attempts 0: read back), None without one."""
    if parts is None or not (parts / f"{key}.pkl").exists():
        return None
    path = parts / f"{key}.pkl"
    fix = f"Delete {path}: its unit is then run again."
    with reading(path, "finished-unit part file", fix), path.open("rb") as f:
        rec: UnitRecord = load_pickle(f)  # part files written before a move load too
    if not isinstance(rec, UnitRecord):
        raise FileFormatError(
            f"The part file {path} holds a {type(rec).__name__}, not a unit record. {fix}",
            path=str(path),
        )
    rec.attempts = 0
    return rec


def write_part(parts: Path | None, rec: UnitRecord) -> None:
    """Write `rec` to ``<parts>/<rec.key>.pkl`` at once (a kill leaves it whole or absent)."""
    if parts is None:
        return
    write_atomic(parts / f"{rec.key}.pkl", pickle.dumps(rec))  # a kill: whole or absent
