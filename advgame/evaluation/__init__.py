"""Robust evaluation: payoff tables of protagonists × adversaries × seeds, and robust metrics.

One `EvalJob` is one cell of the payoff matrix: a protagonist against one adversary set-up over
some seeds. Jobs are pure, picklable values, so `evaluate` runs them in this process or in a
process pool (and the same jobs could be shipped to Ray tasks unchanged). Every episode becomes
one row of a `PayoffTable`, which saves to CSV/JSON and computes the design's robust metrics on
the *true* return: nominal, mean, worst case, CVaR and the degradation from nominal::

    setups = {"nominal": AdversarySetup.nominal(),
              "gauss": AdversarySetup.from_preset("Hopper-v5", "state-gauss-0.1")}
    jobs = population_jobs("Hopper-v5", {"mine": my_policy}, setups, seeds=(0, 1))
    evaluate(jobs, workers=2).metrics(alpha=0.1)

Who is evaluated and against whom, for fixed policies from anywhere: `sb3_protagonist` (an SB3
model trained elsewhere, behind its `VecNormalize` statistics), `team_protagonist`,
`run_protagonist`, `check_protagonists`; `adversary_columns` turns column specs
(``preset:NAME``, ``population:RUN_DIR``, ...) into `AdversarySetup`s; `evaluate_policies` does
all of it and writes a self-contained results folder with its report::

    mine = sb3_protagonist("model.zip", normalizer="vecnormalize.pkl")
    cols = adversary_columns("Hopper-v5", ["preset:state-gauss-0.1", "population:runs/atla"])
    evaluate_policies("Hopper-v5", {"mine": mine}, "results", adversaries=cols)

Jobs and their builders live in `advgame.evaluation.jobs`, tables and metrics in `advgame.evaluation.payoff`,
protagonists in `advgame.evaluation.protagonists`, columns in `advgame.evaluation.columns`; this module re-exports
them, so ``from advgame.evaluation import ...`` reaches all of them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import multiprocessing
import os
import pickle
import sys
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

from advgame.errors import ConfigError
from advgame.evaluation.columns import COLUMN_KINDS, adversary_columns, describe_column
from advgame.evaluation.jobs import (
    SEED_STRIDE,
    AdversarySetup,
    EvalJob,
    budget_sweep,
    population_jobs,
    shift_grid,
)
from advgame.evaluation.payoff import (
    COLUMNS,
    NOMINAL,
    PayoffTable,
    ci95,
    cvar,
    degradation,
    worst_case,
)
from advgame.evaluation.protagonists import (
    check_protagonists,
    run_protagonist,
    sb3_protagonist,
    team_protagonist,
)

__all__ = [
    "COLUMNS",
    "COLUMN_KINDS",
    "NOMINAL",
    "SEED_STRIDE",
    "AdversarySetup",
    "EvalJob",
    "PayoffTable",
    "adversary_columns",
    "budget_sweep",
    "check_protagonists",
    "ci95",
    "cvar",
    "degradation",
    "describe_column",
    "evaluate",
    "evaluate_policies",
    "population_jobs",
    "run_job",
    "run_protagonist",
    "sb3_protagonist",
    "shift_grid",
    "team_protagonist",
    "worst_case",
]

log = logging.getLogger(__name__)


def __getattr__(name: str) -> Any:
    """`evaluate_policies` lives in `advgame.evaluation.suite` (it writes reports), loaded on first use."""
    if name == "evaluate_policies":
        from advgame.evaluation.suite import evaluate_policies

        return evaluate_policies
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


_PRELOAD = ("advgame.evaluation", "advgame.core.episodes", "advgame.scenarios.mujoco", "mujoco")


@contextlib.contextmanager
def _torch_threads(n: int) -> Iterator[None]:
    """Run torch (if this process imported it) on `n` threads, restoring the count after."""
    torch = sys.modules.get("torch")
    before = torch.get_num_threads() if torch is not None else n
    if torch is not None:
        torch.set_num_threads(n)
    try:
        yield
    finally:
        if torch is not None:
            torch.set_num_threads(before)


def run_job(job: EvalJob) -> list[dict[str, Any]]:
    """Play `job`; return one row per episode (`COLUMNS` and the job's tags).

    All episodes of the job (every seed) are played in lockstep, one game each, with the
    policies of one agent asked for all games at once (`advgame.evaluation.batched`); every
    episode is the one a seed plays alone, and policies are built afresh for every episode,
    so a seed's rows do not depend on the job's other seeds. Torch, if imported, runs on one
    thread meanwhile.
    """
    from advgame.evaluation.batched import play_job

    with _torch_threads(1):
        return play_job(job)


def _init_worker(path: list[str]) -> None:
    """Pool initializer: the caller's import path; one thread for torch and BLAS."""
    sys.path[:] = path
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"  # read by torch and BLAS when (and if) a job imports them
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def _run_pickled(blob: bytes) -> list[dict[str, Any]]:
    try:
        job = pickle.loads(blob)
    except Exception as exc:  # e.g. a callable whose module a fresh process cannot import
        raise ConfigError(
            f"A worker process cannot load a job: {type(exc).__name__}: {exc}. Define callables "
            "and specs at module level of an importable module, or use workers=1."
        ) from None
    return run_job(job)


def _pickled(job: EvalJob) -> bytes:
    try:
        return pickle.dumps(job)
    except Exception as exc:
        raise ConfigError(
            f"Job {job.protagonist!r} vs {job.adversary!r} cannot go to a worker process "
            f"({type(exc).__name__}: {exc}). Use module-level functions, not lambdas or "
            "closures, and specs rather than live policies; or use workers=1."
        ) from None


def _warm_forkserver(ctx: Any) -> None:
    """Preload the simulators (and torch and SB3, if used here) in a forkserver yet to start.

    The forkserver then imports them once, and the workers of every later pool start warm.
    """
    from multiprocessing import forkserver

    heavy = [m for m in ("torch", "torch._dynamo", "stable_baselines3") if m in sys.modules]
    server = getattr(forkserver, "_forkserver", None)  # keep what the user asked to preload
    theirs = list(getattr(server, "_preload_modules", None) or ["__main__"])
    ctx.set_forkserver_preload(list(dict.fromkeys([*theirs, *_PRELOAD, *heavy])))


def _pool_map(blobs: list[bytes], workers: int, start_method: str, bar: Any) -> list[list[dict]]:
    out: list[list[dict]] = [[] for _ in blobs]
    ctx = multiprocessing.get_context(start_method)
    if start_method == "forkserver":
        _warm_forkserver(ctx)
    n, path = min(workers, len(blobs)), list(sys.path)
    with ProcessPoolExecutor(n, ctx, initializer=_init_worker, initargs=(path,)) as pool:
        futures = {pool.submit(_run_pickled, b): i for i, b in enumerate(blobs)}
        try:
            for fut in as_completed(futures):
                out[futures[fut]] = fut.result()
                bar.update()
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise
    return out


def evaluate(
    jobs: Iterable[EvalJob],
    workers: int = 1,
    progress: bool = True,
    start_method: str = "forkserver",
) -> PayoffTable:
    """Run `jobs`; return their rows, in job order (whatever the workers), as a `PayoffTable`.

    A pool plays each seed of a job as its own task (the rows are the same: `run_job` builds
    policies afresh per seed), which keeps both workers busy to the end.

    Args:
        jobs: the cells to play.
        workers: 1 plays in this process; more plays in a `ProcessPoolExecutor`.
        progress: show a tqdm progress bar on stderr.
        start_method: ``"forkserver"`` or ``"spawn"`` (not fork: simulators and torch hold
            threads and GL contexts that do not survive it).

    """
    from tqdm.auto import tqdm

    jobs = list(jobs)
    if not all(isinstance(j, EvalJob) for j in jobs):
        raise ConfigError("evaluate() takes EvalJob objects; build them with population_jobs().")
    if type(workers) is not int or workers < 1:
        raise ConfigError(f"workers must be an int >= 1, got {workers!r}.")
    if start_method not in ("forkserver", "spawn"):
        raise ConfigError(f"start_method must be 'forkserver' or 'spawn', got {start_method!r}.")
    pool = workers > 1 and sum(len(j.seeds) for j in jobs) > 1
    units = [dataclasses.replace(j, seeds=(s,)) for j in jobs for s in j.seeds] if pool else jobs
    log.info("evaluating %d jobs (%d tasks) on %d worker(s)", len(jobs), len(units), workers)
    with tqdm(total=len(units), desc="evaluate", file=sys.stderr, disable=not progress) as bar:
        if pool:
            out = _pool_map([_pickled(j) for j in units], workers, start_method, bar)
        else:
            out = []
            for job in units:
                out.append(run_job(job))
                bar.update()
    return PayoffTable(row for rows in out for row in rows)
