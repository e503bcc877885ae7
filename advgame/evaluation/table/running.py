"""Running a table: `evaluate` (jobs -> `PayoffTable`), `run_job`, and the workers' unit.

`evaluate` asks every column about every row first (`advgame.evaluation.table.applicable`), then
cuts the playable jobs into units (lockstep groups in this process, seed units for a pool or
Ray) and runs them on `advgame.runner.run.run_units`. Workers play `run_unit`: the
unit's jobs with each protagonist policy wrapped so that its first action is timed
(`executor.first_action`, the per-job start-up cost in ``jobs.jsonl``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import sys
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from advgame.core.policy import WhiteBox, WhiteBoxForwarder
from advgame.core.progress import count_before
from advgame.core.progress import progress as progress_display
from advgame.errors import ConfigError
from advgame.evaluation.table.applicable import Rows, learn_ahead, not_applicable
from advgame.evaluation.table.jobs import EvalJob, unit_size
from advgame.evaluation.table.payoff import PayoffTable
from advgame.evaluation.table.stored import JobParts, Layout, read_jobs
from advgame.runner.run import EXECUTORS, first_action, run_units, write_timings

__all__ = ["evaluate", "run_job", "run_unit", "use_executor"]

log = logging.getLogger(__name__)


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
    policies of one agent asked for all games at once (`advgame.evaluation.table.batched`); every
    episode is the one a seed plays alone, and policies are built afresh for every episode,
    so a seed's rows do not depend on the job's other seeds. Torch, if imported, runs on one
    thread meanwhile.
    """
    from advgame.evaluation.table.batched import play_job

    with _torch_threads(1):
        return play_job(job)


class _Clocked:
    """A protagonist policy that marks its first action (`executor.first_action`).

    Everything else is forwarded to the policy it wraps; a wrapped white-box policy is wrapped
    in `_ClockedWhiteBox` instead, so that white-box attacks still see a `WhiteBox`.
    """

    def __init__(self, policy: Any) -> None:
        self._policy = policy

    @property
    def wrapped(self) -> Any:
        """The wrapped policy."""
        return self._policy

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._policy, name)
        if name.startswith("act_") and callable(value):  # a batched act_* counts as acting too

            def marked(*args: Any, **kwargs: Any) -> Any:
                first_action()
                return value(*args, **kwargs)

            return marked
        return value

    def reset(self, seed: int | None = None) -> None:
        """Reset the wrapped policy."""
        self._policy.reset(seed)

    def act(self, observation: Any) -> Any:
        """Mark the first action, then act as the wrapped policy."""
        first_action()
        return self._policy.act(observation)


class _ClockedWhiteBox(_Clocked, WhiteBoxForwarder):
    """A `_Clocked` white-box policy: a `WhiteBox` on every Python (3.12+ checks statically)."""


@dataclasses.dataclass(frozen=True)
class _ClockedSpec:
    """Builds `spec` (a spec, policy or callable) wrapped in `_Clocked`."""

    spec: Any

    def build(self, info: Any) -> _Clocked:
        """Build the wrapped policy for `info`'s agent (a `WhiteBox` if the policy is one)."""
        from advgame.core.policy import as_policy

        policy = as_policy(self.spec, info)
        return _ClockedWhiteBox(policy) if isinstance(policy, WhiteBox) else _Clocked(policy)


def _clocked(job: EvalJob) -> EvalJob:
    """`job` with its protagonist policies marking their first action (start-up cost)."""
    prot = job.protagonist_spec
    wrapped = (
        {a: _ClockedSpec(s) for a, s in prot.items()}
        if isinstance(prot, Mapping)
        else _ClockedSpec(prot)
    )
    return dataclasses.replace(job, protagonist_spec=wrapped)


def run_unit(unit: EvalJob | tuple[EvalJob, ...]) -> list[dict[str, Any]]:
    """Play one job or a group of jobs (in lockstep), protagonists timed: what workers run.

    A group's rows are its jobs' rows, job after job (`advgame.evaluation.table.batched.play_jobs`).
    """
    if isinstance(unit, EvalJob):
        return run_job(_clocked(unit))
    from advgame.evaluation.table.batched import play_jobs

    with _torch_threads(1):
        return [row for rows in play_jobs([_clocked(j) for j in unit]) for row in rows]


def evaluate(
    jobs: Iterable[EvalJob],
    workers: int = 1,
    progress: bool = True,
    start_method: str = "forkserver",
    executor: str | None = None,
    address: str | None = None,
    *,
    max_retries: int = 2,
    results_dir: str | Path | None = None,
    ship_files: bool | None = None,
) -> PayoffTable:
    """Run `jobs`; return their rows, in job order (whatever the workers), as a `PayoffTable`.

    With a pool or Ray, what columns learn per protagonist (PA-AD's directors) is learned
    first on the workers (`learn_ahead`). Then every column is asked whether it can play its
    row (`not_applicable`): cells it
    cannot play (a white-box attack against a fixed controller) are not run and are recorded
    in the table's `PayoffTable.not_applicable` with the reason, before any job is queued.

    In this process (local, one worker) consecutive jobs are grouped by up to
    `advgame.evaluation.table.batched.LOCKSTEP_EPISODES` episodes (`lockstep_groups`) and
    every group is one unit, all its episodes played in lockstep with batched policy calls
    across jobs; a pool or Ray gets units of seeds (`split_seeds`, `unit_size`), at least
    three per worker, so a long cell does not hold up a whole table. The rows are the same
    either way, but for the last digits: batched and per-job play round
    differently. Units run on `advgame.runner.run.run_units`, retried when a worker dies.
    With `results_dir`, every finished job is kept in a part file of its own, whatever unit
    played it (`advgame.evaluation.table.stored`), and read back instead of played again,
    with any `workers` and with rows or columns added since.

    Args:
        jobs: the cells to play.
        workers: local: 1 plays in this process, more in a process pool; Ray: units in flight
            at once (and the CPUs of the local Ray it starts if none is running).
        progress: show progress on stderr (`advgame.core.progress`: a bar on a terminal,
            a line every five minutes in a file).
        start_method: local pool: ``"forkserver"`` or ``"spawn"`` (not fork: simulators and
            torch hold threads and GL contexts that do not survive it).
        executor: ``"local"`` or ``"ray"``; None: the default of `use_executor` (``"local"``).
        address: Ray cluster address (``"auto"``, ``"ray://head:10001"``); None: a Ray already
            initialized here, or a new local one.
        max_retries: extra attempts of a unit whose worker died.
        results_dir: a folder for one part file per finished job (``parts/``; a unit's own
            file while a group of jobs is under way) and the units' timings (``jobs.jsonl``:
            pid, start, end, attempts, start-up seconds).
        ship_files: send checkpoint files to the workers as bytes (default: on Ray only).

    """
    jobs = list(jobs)
    if not all(isinstance(j, EvalJob) for j in jobs):
        raise ConfigError("evaluate() takes EvalJob objects; build them with population_jobs().")
    if type(workers) is not int or workers < 1:
        raise ConfigError(f"workers must be an int >= 1, got {workers!r}.")
    kind, address = (executor, address) if executor is not None else _DEFAULT_EXECUTOR
    out = Path(results_dir) if results_dir is not None else None
    parts = out and out / "parts"
    stored = read_jobs(jobs, parts)  # played before: known to be playable
    na = _not_applicable([j for j, r in zip(jobs, stored, strict=True) if r is None],
                         workers, kind, address)  # fmt: skip
    keep = [k for k, j in enumerate(jobs) if (j.protagonist, j.adversary) not in na]
    jobs, stored = [jobs[k] for k in keep], [stored[k] for k in keep]
    todo = [i for i, r in enumerate(stored) if r is None]
    new = [jobs[i] for i in todo]
    if kind == "local" and workers == 1:
        layout = Layout.groups(new, todo)
    else:
        layout = Layout.seeds(new, todo, unit_size(new, workers, kind))
    log.info(
        "evaluating %d jobs (%d units) on %s, %d worker(s)",
        len(todo),
        len(layout.units),
        kind,
        workers,
    )
    kept = len(jobs) - len(todo)
    if kept:
        log.info("%d of %d jobs read back from %s", kept, len(jobs), parts)
    what = f"evaluate ({kept} of {len(jobs)} cells read back)" if kept else "evaluate"
    before = sum(len(r.value) for r in stored if r is not None)  # a row per episode
    shown = _EpisodeProgress(
        layout, what, progress, before, milestones=len(layout.units) < len(todo)
    )
    kept_parts = JobParts(jobs, layout, parts)
    try:
        records = run_units(run_unit, layout.units, executor=kind, workers=workers,
                            address=address, max_retries=max_retries, parts_dir=parts,
                            ship_files=ship_files, start_method=start_method, progress=shown,
                            on_unit=kept_parts.add)  # fmt: skip
    finally:
        shown.bar.close()
    for unit, rec in enumerate(records):  # units that share a key were reported once
        kept_parts.add(unit, rec)
    played = kept_parts.rows
    if out is not None:
        write_timings([r for r in stored if r is not None] + records, out / "jobs.jsonl")
    rows = [played[i] if r is None else r.value for i, r in enumerate(stored)]
    return PayoffTable((row for job_rows in rows for row in job_rows), na)


class _EpisodeProgress:
    """A table's progress counted in episodes (its units differ in size: groups, seeds).

    `before` episodes were read back from job part files (counted, not in the rate). With
    `milestones` (units that hold several cells: lockstep groups in this process, minutes
    each), every finished unit writes its own line, so a log shows each one.
    """

    def __init__(
        self, layout: Layout, what: str, show: bool, before: int, milestones: bool
    ) -> None:
        self.sizes = [sum(n for _, n in owners) for owners in layout.owners]
        self.cells = [len(owners) for owners in layout.owners]
        self.milestones = milestones
        self.played = 0
        self.bar = progress_display(before + sum(self.sizes), what, unit="episode",
                                    initial=before, show=show)  # fmt: skip

    def unit_done(self, index: int, before: bool) -> None:
        """Unit `index` finished (`before`: read back from its part file)."""
        if before:  # not this run's rate
            count_before(self.bar, self.sizes[index])
            return
        self.played += 1
        if self.milestones:
            self.bar.set_postfix_str(f"{self.played} of {len(self.sizes)} groups played "
                                     f"({self.cells[index]} cells)", refresh=False)  # fmt: skip
        self.bar.update(self.sizes[index])


def _not_applicable(
    jobs: list[EvalJob], workers: int, kind: str, address: str | None
) -> dict[tuple[str, str], str]:
    """Learn what `jobs`' columns learn per protagonist, then return the cells they cannot play."""
    with Rows() as rows:  # each row's protagonists built once for both checks
        learned = learn_ahead(jobs, workers=workers, executor=kind, address=address, rows=rows)
        if learned:
            log.info("learned %d per-protagonist attack model(s) on %d worker(s)", learned, workers)
        na = not_applicable(jobs, rows)
    if na:
        log.info("%d cell(s) not applicable, not played: %s", len(na), sorted(na))
    return na


_DEFAULT_EXECUTOR: tuple[str, str | None] = ("local", None)


@contextlib.contextmanager
def use_executor(executor: str, address: str | None = None) -> Iterator[None]:
    """Make `executor` (and `address`) the default of every `evaluate` call inside the block.

    This is how callers that do not pass `executor` (``evaluate_policies``, the CLI's
    ``advgame evaluate --executor ray``) run on Ray with the very same code path.
    """
    global _DEFAULT_EXECUTOR
    if executor not in EXECUTORS:
        raise ConfigError(f"executor must be one of {EXECUTORS}, got {executor!r}.")
    before, _DEFAULT_EXECUTOR = _DEFAULT_EXECUTOR, (executor, address)
    try:
        yield
    finally:
        _DEFAULT_EXECUTOR = before
