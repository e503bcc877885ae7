"""The local back end of `advgame.runner.run.run_units`: this process or a process pool.

The pool is kept warm across calls (until the process exits, or a call needs another size or
import path), so what a job loads (SB3 models: `advgame.agents.common.checkpoint.load_model`
caches them per process; a checkpoint rewritten in place is reloaded, see
`advgame.runner.run`) serves the later jobs of the same worker. A worker that dies breaks a `ProcessPoolExecutor`; the units it and its
fellows were running (each marks its start in a scratch folder) are charged one attempt, the
others go back to the queue free, and a fresh pool carries on.
"""

from __future__ import annotations

import atexit
import multiprocessing
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from advgame.errors import AdvgameError
from advgame.runner.units import (
    Options,
    UnitRecord,
    execute,
    finish,
    init_worker,
    pickled,
    retry,
    scratch_dir,
    ship,
    timed,
)

__all__ = ["run_local", "shutdown"]

_PRELOAD = ("advgame.evaluation", "advgame.core.episodes", "advgame.scenarios.mujoco", "mujoco")


def _warm_forkserver(ctx: Any) -> None:
    """Preload the simulators (and torch and SB3, if used here) in a forkserver yet to start.

    The forkserver then imports them once, and the workers of every later pool start warm.
    """
    from multiprocessing import forkserver

    heavy = [m for m in ("torch", "torch._dynamo", "stable_baselines3") if m in sys.modules]
    server = getattr(forkserver, "_forkserver", None)  # keep what the user asked to preload
    theirs = list(getattr(server, "_preload_modules", None) or ["__main__"])
    ctx.set_forkserver_preload(list(dict.fromkeys([*theirs, *_PRELOAD, *heavy])))


def run_local(
    fn: Callable[[Any], Any], units: Sequence[Any], keys: Sequence[str], opts: Options
) -> list[UnitRecord]:
    """Run the units here (one worker) or in a pool of `opts.workers` processes."""
    recs = [UnitRecord(k) for k in keys]
    if opts.workers == 1 or len(units) <= 1:
        for rec, unit in zip(recs, units, strict=True):
            while True:
                rec.attempts += 1
                rec.extra["submitted"] = time.time()
                try:
                    # no pickling: lambdas and live policies work
                    out = timed(fn, unit, scratch=scratch_dir(opts, rec.key))
                except AdvgameError:
                    raise
                except Exception as exc:
                    if retry(rec, f"{type(exc).__name__}: {exc}", opts):
                        continue
                    break
                finish(rec, out, opts)
                break
        return recs
    fn_blob = pickled(fn)
    blobs = [pickled(u) for u in units]
    files = [ship(u) if opts.ship_files else {} for u in units]
    pending = list(range(len(units)))
    while pending:
        pending = _round(fn_blob, blobs, files, recs, pending, opts)
    return recs


def _marked(
    marks: str, key: str, fn_blob: bytes, blob: bytes, files: dict, scratch: str | None = None
) -> dict[str, Any]:
    """`execute`, leaving a start mark in `marks` that only a finished unit removes."""
    mark = Path(marks) / key
    mark.write_text(str(os.getpid()))
    try:
        return execute(fn_blob, blob, files, scratch)
    finally:
        mark.unlink()


_POOL: dict[str, Any] = {}
"""The warm pool (``"pool"``) and what it was made for (``"key"``: size, start method, path)."""


def _pool(workers: int, start_method: str) -> ProcessPoolExecutor:
    """The process's pool of `workers` workers, kept warm across calls (a new one if broken)."""
    key = (workers, start_method, tuple(sys.path))
    pool = _POOL.get("pool")
    if pool is not None and _POOL["key"] == key and not getattr(pool, "_broken", False):
        return pool
    shutdown()
    ctx = multiprocessing.get_context(start_method)
    if start_method == "forkserver":
        _warm_forkserver(ctx)
    pool = ProcessPoolExecutor(workers, ctx, initializer=init_worker, initargs=(list(sys.path),))
    _POOL.update(pool=pool, key=key)
    return pool


def shutdown(wait: bool = True) -> None:
    """Stop the warm pool's workers (at exit, or when a call needs another pool)."""
    pool = _POOL.pop("pool", None)
    _POOL.pop("key", None)
    if pool is not None:
        pool.shutdown(wait=wait, cancel_futures=True)


atexit.register(shutdown)


def _round(
    fn_blob: bytes,
    blobs: list[bytes],
    files: list[dict],
    recs: list[UnitRecord],
    pending: list[int],
    opts: Options,
) -> list[int]:
    """Run `pending` units on the warm pool; return the units to run again (the pool broke)."""
    marks = tempfile.mkdtemp(prefix="advgame-marks-")
    again: list[int] = []
    settled: set[int] = set()  # finished, or failed for good
    pool = _pool(opts.workers, opts.start_method)
    futures = {}
    try:
        for i in pending:
            recs[i].attempts += 1
            recs[i].extra["submitted"] = time.time()
            args = (marks, recs[i].key, fn_blob, blobs[i], files[i],
                    scratch_dir(opts, recs[i].key))  # fmt: skip
            futures[pool.submit(_marked, *args)] = i
        for fut in as_completed(futures):
            i = futures[fut]
            try:
                out = fut.result()
            except (BrokenProcessPool, AdvgameError):
                raise
            except Exception as exc:
                if retry(recs[i], f"{type(exc).__name__}: {exc}", opts):
                    again.append(i)
                settled.add(i)
                continue
            finish(recs[i], out, opts)
            settled.add(i)
    except BrokenProcessPool:
        shutdown(wait=False)
        again = _after_break(recs, futures, marks, again, settled, opts)
    except BaseException:
        shutdown(wait=False)
        raise
    finally:
        shutil.rmtree(marks, ignore_errors=True)
    return again


def _after_break(
    recs: list[UnitRecord],
    futures: dict,
    marks: str,
    again: list[int],
    settled: set[int],
    opts: Options,
) -> list[int]:
    """A worker died: keep finished results, charge the units that had started, requeue."""
    started = set(os.listdir(marks))
    for fut, i in futures.items():
        if i in settled:
            continue
        rec = recs[i]
        if fut.done() and not fut.cancelled() and fut.exception() is None:
            finish(rec, fut.result(), opts)  # finished before the break, not yet collected
        elif rec.key in started:
            if retry(rec, "the worker process died (killed or out of memory)", opts):
                again.append(i)
        else:
            rec.attempts -= 1  # never started: this attempt does not count
            again.append(i)
    return sorted(set(again))
