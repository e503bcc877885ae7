"""A table's finished cells are kept per job, so any layout of units reads them back.

Real Hopper games with a fixed controller. A stored job's rows are marked (their payoff set to a
value no episode returns), so a cell read back can be told from a cell played again: the marks
must survive a second table with another ``workers``, one with a column added (which shifts every
lockstep group after it), and part files of lockstep groups written before per-job parts existed
(`adopt_groups`). A table stopped half-way keeps the cells it finished, per job, and a
restart with other units plays only the rest.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from advgame.core.policy import CallablePolicy
from advgame.evaluation import AdversarySetup, EvalJob, evaluate, lockstep_groups, population_jobs
from advgame.evaluation.table.batched import LOCKSTEP_EPISODES
from advgame.evaluation.table.running import run_unit
from advgame.evaluation.table.stored import adopt_groups, read_jobs
from advgame.runner.parts import part_key, unit_key
from advgame.runner.run import JobFailedError, run_units
from advgame.runner.units import UnitRecord, read_part, write_part

ENV = "Hopper-v5"
ROOT = Path(__file__).resolve().parents[1]
MARK = -1.0e9


def hop(obs: np.ndarray) -> np.ndarray:
    """A fixed controller (module level: pool workers import it)."""
    return np.clip(-obs[2:5], -1.0, 1.0).astype(np.float32)


def _jobs(*columns: str, seeds: tuple[int, ...] = (0, 1)) -> list[EvalJob]:
    setups = {
        "nominal": AdversarySetup.nominal(),
        "gauss": AdversarySetup.from_preset(ENV, "state-gauss-0.1"),
        "action": AdversarySetup.from_preset(ENV, "action-gauss-0.1"),
    }
    chosen = {c: setups[c] for c in columns}
    return population_jobs(ENV, {"hop": hop, "other": hop}, chosen, seeds=seeds,
                           episodes=1)  # fmt: skip


def _files(folder: Path) -> set[str]:
    return {p.stem for p in (folder / "parts").glob("*.pkl")}


def _mark(parts: Path, key: str) -> None:
    rec = read_part(parts, key)
    assert rec is not None
    rec.value = [{**row, "payoff": MARK} for row in rec.value]
    write_part(parts, rec)


def _marked(table: object, jobs: list[EvalJob]) -> set[tuple[str, str]]:
    cells = {(j.protagonist, j.adversary) for j in jobs}
    rows = table.rows  # type: ignore[attr-defined]
    assert {(r["protagonist"], r["adversary"]) for r in rows} == cells
    return {(r["protagonist"], r["adversary"]) for r in rows if r["payoff"] == MARK}


def _played(folder: Path) -> int:
    lines = (folder / "jobs.jsonl").read_text().splitlines()
    return sum(json.loads(line)["attempts"] > 0 for line in lines)


@pytest.fixture
def pool_imports(monkeypatch: pytest.MonkeyPatch) -> None:
    """Pool workers import this module by name (tests.test_stored_jobs)."""
    monkeypatch.syspath_prepend(str(ROOT))


def test_one_part_per_job_read_back_with_other_workers(tmp_path: Path, pool_imports: None) -> None:
    jobs = _jobs("nominal", "gauss")
    first = evaluate(jobs, workers=1, progress=False, results_dir=tmp_path)
    assert len(lockstep_groups(jobs, LOCKSTEP_EPISODES)) == 1  # played as one group...
    assert _files(tmp_path) == {unit_key(j) for j in jobs}  # ...kept as one part per job
    assert _played(tmp_path) == 1
    for j in jobs:
        _mark(tmp_path / "parts", unit_key(j))
    again = evaluate(jobs, workers=2, progress=False, results_dir=tmp_path)
    assert _marked(again, jobs) == {(j.protagonist, j.adversary) for j in jobs}
    assert _played(tmp_path) == 0
    assert [r["true_return"] for r in again.rows] == [r["true_return"] for r in first.rows]


def test_a_column_added_plays_only_its_cells(tmp_path: Path) -> None:
    jobs = _jobs("nominal", "action")
    evaluate(jobs, workers=1, progress=False, results_dir=tmp_path)
    for j in jobs:
        _mark(tmp_path / "parts", unit_key(j))
    wider = _jobs("nominal", "gauss", "action")  # the new column sits between the old ones
    table = evaluate(wider, workers=1, progress=False, results_dir=tmp_path)
    assert _marked(table, wider) == {(j.protagonist, j.adversary) for j in jobs}
    assert _files(tmp_path) == {unit_key(j) for j in wider}
    assert _played(tmp_path) == 1  # one group of the two new cells


def test_seed_units_on_a_pool_become_job_parts(tmp_path: Path, pool_imports: None) -> None:
    jobs = _jobs("nominal", seeds=(0, 1, 2, 3, 5, 8))
    pooled = evaluate(jobs, workers=2, progress=False, results_dir=tmp_path)
    assert _played(tmp_path) > len(jobs)  # cut into units of seeds...
    assert _files(tmp_path) == {unit_key(j) for j in jobs}  # ...kept per job
    here = evaluate(jobs, workers=1, progress=False)
    assert pooled.rows == here.rows
    again = evaluate(jobs, workers=1, progress=False, results_dir=tmp_path)
    assert _played(tmp_path) == 0 and again.rows == pooled.rows


def broken(obs: np.ndarray) -> np.ndarray:
    """A controller that fails on its first move (module level: pool workers import it)."""
    raise ValueError("broken controller")


def test_a_stopped_table_keeps_its_finished_groups_per_job(
    tmp_path: Path, pool_imports: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("advgame.evaluation.table.stored.LOCKSTEP_EPISODES", 4)
    good = _jobs("nominal", "gauss")  # 4 jobs of 2 episodes: two groups of two
    setups = {"nominal": AdversarySetup.nominal()}
    bad = population_jobs(ENV, {"broken": broken}, setups, seeds=(0, 1), episodes=1)
    with pytest.raises(JobFailedError, match="broken controller"):
        evaluate(good + bad, workers=1, progress=False, results_dir=tmp_path)
    parts = tmp_path / "parts"
    assert all(r is not None for r in read_jobs(good, parts))  # what --status counts
    assert _files(tmp_path) == {unit_key(j) for j in good}  # the groups' own files are gone
    for j in good:
        _mark(parts, unit_key(j))
    again = evaluate(good, workers=2, progress=False, results_dir=tmp_path)  # other units
    assert _marked(again, good) == {(j.protagonist, j.adversary) for j in good}
    assert _played(tmp_path) == 0


def test_a_table_counts_episodes_and_writes_a_line_per_group(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("advgame.evaluation.table.stored.LOCKSTEP_EPISODES", 4)
    jobs = _jobs("nominal", "gauss")
    evaluate(jobs[:2], workers=1, progress=False, results_dir=tmp_path)  # one group played
    capsys.readouterr()
    evaluate(jobs, workers=1, progress=True, results_dir=tmp_path)  # stderr is a file: lines
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "evaluate (" in ln]
    assert len(lines) == 1, lines  # one group left, its own line
    assert "evaluate (2 of 4 cells read back): 8/8 episodes (100 %)" in lines[0]
    assert lines[0].endswith("1 of 1 groups played (2 cells)")


def test_lockstep_group_parts_of_an_earlier_table_are_adopted(tmp_path: Path) -> None:
    old = _jobs("nominal", "action")
    parts = tmp_path / "parts"
    groups = lockstep_groups(old, LOCKSTEP_EPISODES)
    (rec,) = run_units(run_unit, groups, parts_dir=parts)  # how such tables were stored
    _mark(parts, rec.key)
    stale = UnitRecord(key=unit_key(old[0]), value=[{**r, "payoff": 5.0} for r in rec.value[:2]])
    write_part(parts, stale)  # an older table's part of one job: the group's rows replace it
    wider = _jobs("nominal", "gauss", "action")
    cells = {(r["protagonist"], r["adversary"]) for r in rec.value}
    assert adopt_groups(wider, parts, cells) == len(old)
    assert _files(tmp_path) == {unit_key(j) for j in old}  # the group's file is gone
    assert adopt_groups(wider, parts, cells) == 0  # nothing left to split: its file is gone
    table = evaluate(wider, workers=1, progress=False, results_dir=tmp_path)
    assert _marked(table, wider) == cells
    assert _played(tmp_path) == 1


def test_a_group_part_that_does_not_line_up_is_left_alone(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    old = _jobs("nominal")
    parts = tmp_path / "parts"
    (rec,) = run_units(run_unit, lockstep_groups(old, LOCKSTEP_EPISODES), parts_dir=parts)
    rec.value = rec.value[:-1]  # a row short: not the rows of these jobs
    write_part(parts, rec)
    cells = {(j.protagonist, j.adversary) for j in old}
    assert adopt_groups(old, parts, cells) == 0
    assert _files(tmp_path) == {rec.key} and "not split per job" in caplog.text


@dataclass(frozen=True)
class FileHop:
    """`hop` scaled by a gain read from a file: a spec that names a file, as checkpoints do."""

    path: str

    def __post_init__(self) -> None:
        if not Path(self.path).is_file():  # as a spec may check (LocalModel does)
            raise FileNotFoundError(self.path)

    def build(self, info: object) -> CallablePolicy:
        """The controller with the file's gain."""
        gain = float(Path(self.path).read_text())
        return CallablePolicy(lambda obs: np.clip(gain * hop(obs), -1.0, 1.0))


def _file_jobs(path: str) -> list[EvalJob]:
    setups = {"nominal": AdversarySetup.nominal()}
    return population_jobs(ENV, {"file": FileHop(path)}, setups, seeds=(0,), episodes=1)


def test_part_files_are_found_from_another_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A campaign run as ``zoo/x.toml`` from the root and as ``x.toml`` from ``zoo/`` alike."""
    (tmp_path / "zoo" / "run").mkdir(parents=True)
    (tmp_path / "zoo" / "run" / "gain.txt").write_text("0.5")
    monkeypatch.chdir(tmp_path)
    jobs = _file_jobs("zoo/run/gain.txt")  # the paths as given from the root
    evaluate(jobs, workers=1, progress=False, results_dir=Path("zoo/results"))
    (job,) = jobs
    assert part_key(job, Path("zoo/results/parts")) != unit_key(job)  # the file is rebased
    _mark(tmp_path / "zoo" / "results" / "parts", part_key(job, Path("zoo/results/parts")))
    monkeypatch.chdir(tmp_path / "zoo")
    again = _file_jobs("run/gain.txt")  # the same file, from zoo/
    table = evaluate(again, workers=1, progress=False, results_dir=Path("results"))
    assert _marked(table, again) == {("file", "nominal")}
    assert _played(tmp_path / "zoo" / "results") == 0
    moved = tmp_path / "elsewhere"  # the folder cloned elsewhere: run and results together
    (tmp_path / "zoo").rename(moved)
    monkeypatch.chdir(moved)
    table = evaluate(
        _file_jobs("run/gain.txt"), workers=1, progress=False, results_dir=Path("results")
    )
    assert _marked(table, again) == {("file", "nominal")}
    other = _file_jobs(os.path.join("run", "gain.txt"))[0]
    (moved / "run" / "gain.txt").unlink()  # a file that is not there any more: left as given
    assert part_key(other, Path("results/parts")) == unit_key(other)


def test_part_files_named_before_part_keys_are_read_back_and_renamed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "gain.txt").write_text("0.5")
    monkeypatch.chdir(tmp_path)
    jobs = _file_jobs("gain.txt")
    evaluate(jobs, workers=1, progress=False, results_dir=tmp_path / "out")
    parts = tmp_path / "out" / "parts"
    (job,) = jobs
    new, old = part_key(job, parts), unit_key(job)
    _mark(parts, new)
    (parts / f"{new}.pkl").rename(parts / f"{old}.pkl")  # named as before part_key
    table = evaluate(jobs, workers=1, progress=False, results_dir=tmp_path / "out")
    assert _marked(table, jobs) == {("file", "nominal")} and _played(tmp_path / "out") == 0
    assert _files(tmp_path / "out") == {new}  # renamed: found from any folder from now on
