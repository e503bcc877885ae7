"""Where a campaign stands: its runs' folders, ``status.json``, what is left, the curves so far.

`advgame.workflows.campaign.run_campaign` keeps ``status.json`` current with `write_status`;
``advgame campaign FILE --status`` prints it, counts what the evaluate stage has left
(`search_status`, `table_status`) and draws every method's training curves so far
(`progress_curves`), runs in training and parked ones included.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from advgame.core.config import read_json, write_atomic
from advgame.workflows.campaign_grid import Campaign

__all__ = [
    "EVALUATION_CURVES",
    "FINISHED",
    "PROGRESS_CURVES",
    "RATE_ITERATIONS",
    "done_runs",
    "evaluation_curves",
    "progress",
    "progress_curves",
    "progress_files",
    "run_dir",
    "search_status",
    "seconds_left",
    "table_status",
    "write_status",
]

FINISHED = "finished"
"""The campaign's folder of finished, compacted runs (``runs/`` holds those in training)."""


def run_dir(out: Path, run: str) -> Path:
    """Where run `run` of the campaign in `out` is: ``finished/RUN`` once done, else ``runs/RUN``."""
    done = out / FINISHED / run
    return done if done.exists() else out / "runs" / run


def progress(run: Path) -> int:
    """The last finished iteration of the run in folder `run` (0: none)."""
    if not (run / "state.json").exists():
        return 0
    return int(read_json(run / "state.json", "run state", ("iteration",))["iteration"])


def write_status(campaign: Campaign, out: Path, training: Sequence[str] = ()) -> dict[str, Any]:
    """Write ``status.json``: each run's state and iteration, and the evaluation's.

    A run is ``training`` when it is in `training` or another live process claims it
    (`advgame.workflows.claims`), as when the evaluate stage runs beside the train stage.
    """
    from advgame.workflows.claims import holder
    from advgame.workflows.park import parked_copies, parked_iteration

    runs = {}
    for r in campaign.runs():
        it, of = progress(run_dir(out, r)), campaign.config(r).iterations
        if it < of:  # a run parked further on than runs/ holds resumes from there
            it = max(it, *(parked_iteration(p) for p in parked_copies(out, r)))
        busy = r in training or holder(out, r) is not None  # this process or another
        state = "done" if it >= of else ("training" if busy else "partial" if it else "pending")
        runs[r] = {"state": state, "iteration": it, "of": of}
    table = out / "campaign.md"
    status = {
        "scenario": campaign.scenario,
        "runs": runs,
        "evaluated": sorted(_evaluated(out)),
        "table": table.name if table.exists() else None,
    }
    write_atomic(out / "status.json", json.dumps(status, indent=2) + "\n")
    return status


def done_runs(status: dict[str, Any]) -> list[str]:
    """The finished runs of a `write_status` result, in the campaign's order."""
    return [r for r, s in status["runs"].items() if s["state"] == "done"]


def search_status(campaign: Campaign, out: Path, done: Sequence[str]) -> dict[str, int] | None:
    """How far the optimal attack's search has come for the finished runs `done` (None: no search).

    ``{"trained", "candidates", "trained_steps", "steps"}``: candidates whose part file exists
    (`advgame.evaluation.attacks.optimal.candidate_jobs`), and their adversary steps, out of
    all; what is left is what the evaluate stage still trains. Part files are named with the
    runs' files relative to them (`advgame.runner.parts.part_key`), so any folder will do.
    """
    search = campaign.search()
    if search is None:
        return None
    from advgame.evaluation.table.protagonists import run_protagonist
    from advgame.runner.parts import has_part
    from advgame.workflows.cells import search_jobs

    protagonists = {r: run_protagonist(run_dir(out, r))[1] for r in done}
    jobs = search_jobs(campaign.scenario, protagonists, search, threat=campaign.threat)
    parts = out / "results" / "optimal" / "parts"
    have = [has_part(parts, j) for j in jobs]
    return {
        "trained": sum(have),
        "candidates": len(jobs),
        "trained_steps": sum(j.steps for j, h in zip(jobs, have, strict=True) if h),
        "steps": sum(j.steps for j in jobs),
    }


def table_status(campaign: Campaign, out: Path, done: Sequence[str]) -> dict[str, int]:
    """How many cells of the evaluate stage's table for the finished runs `done` are played.

    ``{"played", "cells"}``: cells kept in part files (`advgame.evaluation.table.stored`) out
    of the table's cells, without the ``attack optimal`` column (its cells depend on the
    search, `search_status`). Nothing is played or learned; call it as `search_status`.
    """
    from advgame.evaluation.table.protagonists import run_protagonist
    from advgame.evaluation.table.stored import read_jobs
    from advgame.workflows.cells import table_jobs

    runs = {r: run_dir(out, r) for r in done}
    if not runs:
        return {"played": 0, "cells": 0}
    protagonists = {r: run_protagonist(d)[1] for r, d in runs.items()}
    _, jobs = table_jobs(campaign.scenario, protagonists, campaign.adversaries, runs=runs,
                         seeds=campaign.eval_seeds, threat=campaign.threat)  # fmt: skip
    stored = read_jobs(jobs, out / "results" / "parts")
    return {"played": sum(r is not None for r in stored), "cells": len(jobs)}


def _evaluated(out: Path) -> set[str]:
    """Runs that have rows in the campaign's payoff table."""
    path = out / "results" / "payoff.csv"
    if not path.exists():
        return set()
    from advgame.evaluation import PayoffTable

    return set(PayoffTable.from_csv(path).protagonists)


PROGRESS_CURVES = "progress.png"
"""The figure `progress_curves` writes in a campaign's folder (``campaign.md`` has ``curves.png``)."""


def _rows(path: Path) -> int:
    """Data rows of a progress CSV (0: none, or no file)."""
    if not path.is_file():
        return 0
    with path.open() as f:
        return max(sum(1 for line in f if line.strip()) - 1, 0)


def progress_files(campaign: Campaign, out: Path) -> dict[str, Path]:
    """Each run's furthest ``progress.csv``: of ``finished/``, ``runs/`` and its parked copies.

    Runs that have not trained an iteration anywhere are left out.
    """
    from advgame.workflows.park import parked_copies

    files = {}
    for r in campaign.runs():
        folders = [out / FINISHED / r, out / "runs" / r, *parked_copies(out, r)]
        copies = (folder / "progress.csv" for folder in folders)
        rows = {path: _rows(path) for path in copies}  # each file counted once
        furthest = max(rows, key=rows.__getitem__)  # the first of equals: finished, then runs/
        if rows[furthest]:
            files[r] = furthest
    return files


def progress_curves(campaign: Campaign, out: Path) -> Path | None:
    """Write ``progress.png`` in `out`: each method's training curves so far; return its path.

    Every run that has trained counts, finished, in training or parked (`progress_files`); a
    method's line is the mean over the runs that have reached each point, its band their
    minimum and maximum, so a multi-session campaign's figure can be read while it trains.
    None (and nothing written) when no run has trained an iteration.
    """
    from advgame.reports.campaign import method_curves

    files = progress_files(campaign, out)
    if not files:
        return None
    title = f"{campaign.scenario}: {out.name}, {len(files)} of {len(campaign.runs())} runs so far"
    return method_curves(campaign, files, out / PROGRESS_CURVES, ragged=True, title=title)


EVALUATION_CURVES = "evaluation.png"
"""The figure `evaluation_curves` writes in a campaign's folder (numbers beside it, ``.csv``)."""


def evaluation_curves(campaign: Campaign, out: Path) -> Path | None:
    """Write ``evaluation.png``: each method's in-training evaluation per test condition.

    The curves the Robust Gymnasium paper's Figure 3 draws: one panel per condition of the
    runs' ``eval_conditions`` (`advgame.training.conditions`), a method's line the mean over its
    runs of the deterministic protagonist's mean true return at each point, its band their
    minimum and maximum; runs in training and parked ones count (`progress_files`), runs
    trained without the conditions are left out. None (nothing written) when no run has a point.
    """
    from advgame.reports.campaign import method_curves
    from advgame.training.conditions import condition_column

    specs = [c for r in campaign.runs() for c in campaign.config(r).eval_conditions or ()]
    columns = [condition_column(c) for c in dict.fromkeys(specs)]
    files = {r: f for r, f in progress_files(campaign, out).items() if _has(f, columns)}
    if not columns or not files:
        return None
    title = f"{campaign.scenario}: deterministic evaluation during training ({out.name})"
    return method_curves(
        campaign, files, out / EVALUATION_CURVES, ragged=True, title=title, columns=columns
    )


def _has(path: Path, columns: Sequence[str]) -> bool:
    """Whether the CSV at `path` has every one of `columns` (its header says)."""
    with path.open() as f:
        header = f.readline().strip().split(",")
    return all(c in header for c in columns)


RATE_ITERATIONS = 3
"""Last iterations of a run whose mean wall time `seconds_left` estimates the rest from."""


def _iteration_seconds(path: Path) -> float | None:
    """Mean wall seconds of the last `RATE_ITERATIONS` iterations of a progress CSV (None: none)."""
    from advgame.reports.plots import read_progress

    wall = read_progress(path).get("wall_s", np.array([]))
    wall = wall[np.isfinite(wall)]
    return float(wall[-RATE_ITERATIONS:].mean()) if len(wall) else None


def seconds_left(campaign: Campaign, out: Path, status: dict[str, Any]) -> dict[str, float | None]:
    """Wall seconds of one worker each unfinished run of `status` still needs, estimated.

    A run that has trained is timed at the mean of its last `RATE_ITERATIONS` iterations
    (``wall_s`` of its furthest ``progress.csv``); one that has not, at the mean of its
    method's runs that have. None where neither has a measured rate. The rates are what the
    runs took where they trained: beside another run on the same cores, as campaigns train.
    """
    files = progress_files(campaign, out)
    rate = {r: _iteration_seconds(f) for r, f in files.items()}
    left: dict[str, float | None] = {}
    for method in campaign.methods:
        runs = campaign.method_runs(method)
        known = [v for r in runs if (v := rate.get(r)) is not None]
        fallback = float(np.mean(known)) if known else None
        for r in runs:
            s = status["runs"][r]
            if s["state"] == "done":
                continue
            per = rate.get(r) if rate.get(r) is not None else fallback
            left[r] = None if per is None else per * (s["of"] - s["iteration"])
    return left
