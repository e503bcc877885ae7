"""A table's finished cells on disk: one part file per job, whatever the units that played it.

`advgame.evaluation.evaluate` plays jobs in units that depend on how it runs (lockstep groups
of consecutive jobs in this process, units of seeds on a pool or Ray), and a unit's part file is
named after the unit. Named that way alone, a table played again with another ``workers``, or
with rows or columns added (which shift every lockstep group after them), would find none of its
finished cells and play them again; and since batched and per-job play round differently in
chaotic dynamics, the numbers would move in their last digits. So once a unit is played its
rows are also kept per job (`JobParts`, ``<parts>/<job key>.pkl``, the key `part_key` gives
the job: its files named relative to ``parts``, so it holds from any folder), and a table reads
its finished jobs back from those (`read_jobs`) before it cuts the rest into units. A job's part
is written as soon as its last unit finishes, not at the end of the table, so an interrupted
table keeps its finished cells whatever units play the rest. A unit that is its job (a whole job
on a pool) is its own job part.

`adopt_groups` splits part files of lockstep groups written before per-job parts existed into
per-job parts, given the cells of the table they were played for (`adopt_earlier_table`: the
cells of the ``payoff.csv`` beside them).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any

from advgame.evaluation.table.batched import LOCKSTEP_EPISODES
from advgame.evaluation.table.jobs import EvalJob, lockstep_groups, split_seeds
from advgame.runner.parts import part_key, read_unit_part
from advgame.runner.units import UnitRecord, write_part

__all__ = [
    "JobParts",
    "Layout",
    "adopt_earlier_table",
    "adopt_groups",
    "read_jobs",
    "store_jobs",
]

log = logging.getLogger(__name__)


def read_jobs(jobs: Sequence[EvalJob], parts: Path | None) -> list[UnitRecord | None]:
    """Each job's stored record (its rows in ``value``), None for a job not played yet."""
    if parts is None:
        return [None] * len(jobs)
    return [read_unit_part(parts, j) for j in jobs]


@dataclasses.dataclass
class Layout:
    """Units cut from jobs, and which job each stretch of a unit's rows belongs to."""

    units: list[Any]
    """What `advgame.runner.run.run_units` runs: jobs, jobs of fewer seeds, or groups."""
    owners: list[list[tuple[int, int]]]
    """Per unit, ``(job index, rows)`` in the order of its rows: one row per episode."""

    @classmethod
    def groups(cls, jobs: Sequence[EvalJob], index: Sequence[int]) -> Layout:
        """Lockstep groups of `jobs` (`lockstep_groups`); `index` numbers the jobs."""
        at = dict(zip(map(id, jobs), index, strict=True))
        units: list[Any] = lockstep_groups(jobs, LOCKSTEP_EPISODES)
        owners = [[(at[id(j)], _rows(j)) for j in group] for group in units]
        return cls(units, owners)

    @classmethod
    def seeds(cls, jobs: Sequence[EvalJob], index: Sequence[int], per_unit: int) -> Layout:
        """Each job cut into units of at most `per_unit` seeds (`split_seeds`'s order)."""
        units: list[Any] = []
        owners = []
        for job, i in zip(jobs, index, strict=True):
            for part in split_seeds([job], per_unit):
                units.append(part)
                owners.append([(i, _rows(part))])
        return cls(units, owners)


def _rows(job: EvalJob) -> int:
    return len(job.seeds) * job.episodes


class JobParts:
    """Each job's rows, kept in its part file the moment the last unit holding them is in.

    Fed every unit's record once (`add`, as `advgame.runner.run.run_units` reports them through
    ``on_unit``), so a table interrupted half-way keeps its finished cells per job: a restart
    with other units (another ``workers``) reads them back, and ``advgame campaign --status``
    counts them. A unit part whose jobs are all kept is removed; a unit that is its whole job
    is its own job part already.
    """

    def __init__(self, jobs: Sequence[EvalJob], layout: Layout, parts: Path | None) -> None:
        self.jobs, self.layout, self.parts = jobs, layout, parts
        self.rows: dict[int, list[dict[str, Any]]] = {}
        """The rows of each job whose units are all in, by job index."""
        self._waiting: dict[int, int] = {}
        for owners in layout.owners:
            for i, _ in owners:
                self._waiting[i] = self._waiting.get(i, 0) + 1
        self._chunks: dict[int, dict[int, list[dict[str, Any]]]] = {}
        self._records: dict[int, UnitRecord] = {}
        self._keys: dict[int, str] = {}

    def _key(self, i: int) -> str:
        """Job `i`'s part key (a digest of the job: computed once)."""
        if i not in self._keys:
            self._keys[i] = part_key(self.jobs[i], self.parts)
        return self._keys[i]

    def add(self, unit: int, rec: UnitRecord) -> None:
        """Unit number `unit` of the layout finished with `rec` (a unit given again is ignored)."""
        if unit in self._records:
            return
        self._records[unit] = rec
        at = 0
        for i, n in self.layout.owners[unit]:
            chunk = rec.value[at : at + n]
            at += n
            _check(self.jobs[i], chunk, n, self.layout.units[unit])
            self._chunks.setdefault(i, {})[unit] = chunk
            self._waiting[i] -= 1
        if at != len(rec.value):
            raise RuntimeError(f"unit {rec.key} has {len(rec.value)} rows, its jobs {at}")
        for i, _ in self.layout.owners[unit]:
            if not self._waiting[i]:
                self._keep(i)

    def _keep(self, i: int) -> None:
        """Job `i`'s units are all in: join its rows in the units' order, write its part."""
        chunks = self._chunks.pop(i)
        self.rows[i] = [row for u in sorted(chunks) for row in chunks[u]]
        if self.parts is None:
            return
        key = self._key(i)
        sources = [self._records[u] for u in sorted(chunks)]
        if [r.key for r in sources] != [key]:  # not a unit that is its whole job
            write_part(self.parts, _job_record(key, self.rows[i], sources[-1]))
        for u in chunks:
            owned = self.layout.owners[u]
            mine = {self._key(j) for j, _ in owned}
            if all(j in self.rows for j, _ in owned) and self._records[u].key not in mine:
                (self.parts / f"{self._records[u].key}.pkl").unlink(missing_ok=True)


def store_jobs(
    jobs: Sequence[EvalJob], layout: Layout, records: Sequence[UnitRecord], parts: Path | None
) -> dict[int, list[dict[str, Any]]]:
    """Split the units' rows per job; keep each job's in its own part file; return them by index.

    `JobParts` fed every record at once (the units of an earlier table, `adopt_groups`).
    """
    kept = JobParts(jobs, layout, parts)
    for unit, rec in enumerate(records):
        kept.add(unit, rec)
    return kept.rows


def _job_record(key: str, rows: list[dict[str, Any]], unit: UnitRecord) -> UnitRecord:
    return UnitRecord(key=key, value=rows, attempts=unit.attempts, pid=unit.pid, host=unit.host,
                      start=unit.start, end=unit.end, extra={"unit": unit.key})  # fmt: skip


def _check(job: EvalJob, chunk: list[dict[str, Any]], n: int, unit: Any) -> None:
    names = {(r.get("protagonist"), r.get("adversary")) for r in chunk}
    if len(chunk) != n or names != {(job.protagonist, job.adversary)}:
        raise RuntimeError(
            f"the rows of unit {unit!r} do not line up with its jobs at {job.protagonist!r} vs "
            f"{job.adversary!r} ({len(chunk)} rows for {n} episodes, names {sorted(names)})"
        )


def adopt_groups(jobs: Sequence[EvalJob], parts: Path, cells: Collection[tuple[str, str]]) -> int:
    """Split a lockstep-grouped table's part files into per-job parts; return the jobs adopted.

    `cells` are the (protagonist, adversary) cells of the table the groups were played for
    (its ``payoff.csv``); the jobs of those cells, in `jobs`' order, grouped as one process
    grouped them then (`lockstep_groups`), name the group part files. Each group found is split
    (`store_jobs`, which removes the group's file), its rows replacing any older part of one of
    its jobs: the group's rows are the ones that table shows. Jobs whose specs changed since
    name other groups and are not adopted.
    """
    cells = set(cells)
    old = [(i, j) for i, j in enumerate(jobs) if (j.protagonist, j.adversary) in cells]
    if not old or not parts.is_dir():
        return 0
    layout = Layout.groups([j for _, j in old], [i for i, _ in old])
    adopted = 0
    for unit, owners in zip(layout.units, layout.owners, strict=True):
        rec = read_unit_part(parts, unit)
        if rec is None:
            continue
        try:
            store_jobs(jobs, Layout([unit], [owners]), [rec], parts)
        except RuntimeError as e:  # a file of another table under the same name: left alone
            log.warning("part file %s not split per job: %s", rec.key, e)
            continue
        adopted += len(owners)
    if adopted:
        log.info("split %d jobs' rows out of lockstep-group part files in %s", adopted, parts)
    return adopted


def adopt_earlier_table(jobs: Sequence[EvalJob], out: Path) -> int:
    """`adopt_groups` for the table last written to `out` (``payoff.csv`` names its cells).

    Tables played in one process before 27 Nov 2026 kept a part file per lockstep group in
    ``out/parts``; a table with a row or column added would otherwise play them all again.
    """
    from advgame.evaluation.table.payoff import PayoffTable

    last, parts = out / "payoff.csv", out / "parts"
    if not (last.is_file() and parts.is_dir()):
        return 0
    rows = PayoffTable.from_csv(last).rows
    return adopt_groups(jobs, parts, {(r["protagonist"], r["adversary"]) for r in rows})
