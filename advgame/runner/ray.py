"""The Ray back end of `advgame.runner.run.run_units`: Ray core tasks.

Each unit is one task needing one CPU; at most ``workers`` units are in flight at once (on
a cluster, pass the number of CPUs to use). Ray keeps its worker processes alive and reuses them
for later tasks of the same job, so checkpoints a worker loaded stay cached (warm workers).
Tasks are submitted with ``max_retries=0`` and retried here, so that a unit's attempts are
counted and bounded the same way as on the local pool: a crashed worker (killed, out of
memory, a lost node) or a non-advgame exception costs one attempt.

Shipped files are put in the object store once per distinct set of files and passed as a
top-level argument, which Ray resolves on the worker's node (no shared file system needed).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from typing import Any

from advgame.errors import AdvgameError, MissingExtraError
from advgame.runner.units import Options, UnitRecord, execute, finish, pickled, retry, ship

__all__ = ["connect", "run_ray"]

log = logging.getLogger(__name__)
_REMOTE: dict[str, Any] = {}


def _ray() -> Any:
    try:
        import ray
    except ImportError:
        raise MissingExtraError(
            "executor='ray' needs Ray: pip install 'advgame[ray]' (Ray core, pinned in "
            "constraints.txt), or use executor='local'."
        ) from None
    return ray


def connect(address: str | None, workers: int) -> Any:
    """Return the `ray` module, initialized: attach to `address`, or start a local Ray."""
    ray = _ray()
    if ray.is_initialized():
        return ray
    env = {"env_vars": {v: "1" for v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}}
    if address is None:
        log.info("starting a local Ray with %d CPUs", workers)
        ray.init(num_cpus=workers, include_dashboard=False, runtime_env=env)
    else:
        log.info("connecting to the Ray cluster at %s", address)
        ray.init(address=address, runtime_env=env)
    return ray


def _remote(ray: Any) -> Any:
    if "execute" not in _REMOTE:
        _REMOTE["execute"] = ray.remote(num_cpus=1, max_retries=0)(execute)
    return _REMOTE["execute"]


def run_ray(
    fn: Callable[[Any], Any], units: Sequence[Any], keys: Sequence[str], opts: Options
) -> list[UnitRecord]:
    """Run the units as Ray tasks (`opts.address`, or a local Ray of `opts.workers` CPUs)."""
    ray = connect(opts.address, opts.workers)
    task = _remote(ray)
    fn_ref = ray.put(pickled(fn))
    recs = [UnitRecord(k) for k in keys]
    blobs = [ray.put(pickled(u)) for u in units]
    file_refs: dict[tuple[str, ...], Any] = {}
    args = []
    for u in units:
        files = ship(u) if opts.ship_files else {}
        ident = tuple(sorted(files))
        if ident not in file_refs:
            file_refs[ident] = ray.put(files)
        args.append(file_refs[ident])
    inflight: dict[Any, int] = {}

    def submit(i: int) -> None:
        recs[i].attempts += 1
        recs[i].extra["submitted"] = time.time()
        inflight[task.remote(fn_ref, blobs[i], args[i])] = i

    queue = list(range(len(units)))[::-1]
    try:
        while queue or inflight:
            while queue and len(inflight) < opts.workers:  # at most `workers` units in flight
                submit(queue.pop())
            (ref,), _ = ray.wait(list(inflight), num_returns=1)
            i = inflight.pop(ref)
            try:
                out = ray.get(ref)
            except ray.exceptions.RayTaskError as exc:  # the unit raised
                cause = getattr(exc, "cause", None)
                if isinstance(cause, AdvgameError):
                    raise cause from None
                error = f"{type(cause).__name__}: {cause}" if cause else str(exc)
                if retry(recs[i], error, opts):
                    queue.append(i)
                continue
            except ray.exceptions.RayError as exc:  # the worker (or its node) died
                if retry(recs[i], f"{type(exc).__name__}: {str(exc).splitlines()[0]}", opts):
                    queue.append(i)
                continue
            finish(recs[i], out, opts)
    except BaseException:
        for ref in inflight:
            ray.cancel(ref, force=True)
        raise
    return recs
