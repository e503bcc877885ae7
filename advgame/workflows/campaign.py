"""Campaigns: a grid of methods × seeds trained, evaluated in one threat model, and tabled.

A campaign file (TOML) names a scenario, the methods (`advgame.training.METHODS`) and seeds,
the training budget shared by every run and per method, and the evaluation (columns, seeds,
the threat model, the optimal attack's budget)::

    scenario = "Hopper-v5"
    methods = ["ppo", "atla"]
    seeds = [0, 1, 2]
    zoo = "hopper"             # --release: the zoo folder (default: the scenario's name)

    [train]                    # TrainConfig fields for every run
    iterations = 976
    protagonist_steps = 2048

    [train.atla]               # and for one method
    adversary_steps = 2048
    seeds = [0, 1, 2, 3, 4]    # (its own seeds: more where the intervals overlap)

A name in ``methods`` may also be a variant of a method: its section says which method it
varies, and the rest of the section is the variation (a training preset, hyper-parameters)::

    methods = ["crpo", "crpo-noisy"]

    [train.crpo-noisy]
    method = "crpo"
    preset = "action-gauss-0.3"

    [evaluate]
    adversaries = ["attacks"]  # column specs (advgame.evaluation.table.columns)
    threat = "atla"
    seeds = 10
    exploitability = 0         # steps of the searched optimal attack (0: none)
    optimal_grid = { 4 = { steps_scale = 10 } }  # overrides of OPTIMAL_GRID entries, by index
    cost_limit = 25            # safe scenarios: add the cost table (episode cost ≤ limit)

`run_campaign` trains every run that is not finished, two (``workers``) at a time as jobs on
the executor (a local process pool or Ray); a run that was interrupted resumes from its last
iteration (``runs/``), a finished one is compacted to its last checkpoint and moved to
``finished/`` in one rename (small enough to commit; never trained again); a resumed run
takes the campaign's in-training evaluation (``eval_episodes``, ``eval_conditions``), whose
points the train stage draws in ``evaluation.png`` (`evaluation_curves`). A run parked in
``parked/`` or ``$ADVGAME_PARK`` (`park_campaign`, `advgame.workflows.park`: how a run longer
than a session crosses to another session) is rebuilt in ``runs/`` first when it is further
on than the copy there, and its parked copies deleted once it is finished. It then evaluates every finished run's
final protagonist in one table (finished evaluation units are read back, not replayed) and
writes ``campaign.md`` / ``campaign.csv``: per method, the median agent by worst-of-adversaries
return (attack and preset columns alike), the interquartile range and the 95 % interval over
seeds of its natural and worst-of-adversaries returns; per method and column, the mean return
over its agents (``campaign_columns.csv``); or, with a ``cost_limit`` (safe scenarios), per
method and column the return and episode cost (means over seeds with 95 % intervals) and
the share of evaluation episodes whose cost stays within the limit. ``status.json`` says at every step what is done.
The train stage claims each run it trains (`advgame.workflows.claims`), so a second train
stage started beside it leaves those runs alone and trains only the others.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from advgame.core.config import read_json
from advgame.errors import ConfigError
from advgame.reports.campaign import campaign_table
from advgame.workflows.campaign_grid import Campaign, load_campaign
from advgame.workflows.campaign_status import (
    FINISHED,
    done_runs,
    evaluation_curves,
    progress_curves,
    run_dir,
    search_status,
    seconds_left,
    table_status,
    write_status,
)
from advgame.workflows.campaign_status import progress as _progress
from advgame.workflows.claims import claim_path, claimed, release

__all__ = [
    "FINISHED",
    "Campaign",
    "campaign_table",
    "compact",
    "done_runs",
    "evaluation_curves",
    "load_campaign",
    "park_campaign",
    "progress_curves",
    "run_campaign",
    "run_dir",
    "search_status",
    "seconds_left",
    "table_status",
    "write_status",
]

log = logging.getLogger(__name__)


class _StatusEach:
    """Rewrites ``status.json`` each time a run finishes (the executor's progress hook)."""

    def __init__(self, campaign: Campaign, out: Path, training: Sequence[str], show: bool) -> None:
        from advgame.core.progress import LineProgress, Silent

        self.campaign, self.out, self.training = campaign, out, training
        self.bar: Any = (  # runs differ in length (and some resume): no estimate of the rest
            LineProgress(len(training), f"campaign {out.name}", unit="run", estimate=False)
            if show
            else Silent()
        )

    def update(self) -> None:
        """One more unit finished: record what is on disk now."""
        status = write_status(self.campaign, self.out, training=self.training)
        done = [r for r in self.training if status["runs"][r]["state"] == "done"]
        self.bar.set_postfix_str(f"finished: {', '.join(done)}", refresh=False)
        self.bar.update()


def _train_unit(unit: tuple[Any, str, str, bool | str]) -> str:
    """Train or resume one run to its end, then keep it compact in ``finished/`` (a worker)."""
    from advgame.training import resume, train
    from advgame.training.conditions import EVAL_FIELDS

    config, partial, finished, show = unit
    path = Path(partial)
    if (path / "config.json").exists():  # with the campaign's in-training evaluation now
        resume(path, progress=show, evaluation={f: getattr(config, f) for f in EVAL_FIELDS})
    else:
        train(config, path, progress=show)
    compact(path)
    Path(finished).parent.mkdir(parents=True, exist_ok=True)
    path.rename(finished)  # one rename: ``finished/`` never holds half a run
    return finished


def compact(run: Path) -> None:
    """Keep what a finished run is evaluated and released from: its last checkpoint.

    Earlier checkpoint folders, TensorBoard's event files and the off-policy learners' replay
    buffers (only a resume reads one, and a finished run never trains again) are deleted, and
    the population keeps the members whose files remain, so a finished run is a few hundred KB
    (a few MB for the 256-wide networks of OMPO, RSC and DBC) that can be committed
    (``config.json``, ``state.json``, ``population.json``, ``progress.csv``, the last
    checkpoint). The learners' logged scalars (losses, temperature, fps) stay, as
    ``learning.csv`` (`advgame.training.scalars.export_scalars`).
    """
    import shutil

    from advgame.training.population import Population
    from advgame.training.scalars import export_scalars

    state = read_json(run / "state.json", "run state", ("checkpoint",))
    last = (run / state["checkpoint"]).resolve()
    for folder in (run / "checkpoints").iterdir():
        if folder.resolve() != last:
            shutil.rmtree(folder)
    export_scalars(run / "tb", run / "learning.csv")
    shutil.rmtree(run / "tb", ignore_errors=True)
    for replay in last.glob("*_replay.pkl"):
        replay.unlink()
    population = Population.load(run / "population.json")
    population.drop_missing()
    population.save(run / "population.json")


def run_campaign(
    campaign: Campaign,
    out: str | Path,
    *,
    workers: int = 2,
    executor: str = "local",
    address: str | None = None,
    stage: str = "all",
    max_runs: int | None = None,
    progress: bool = True,
    only: Sequence[str] | None = None,
    park_every: float = 0.0,
) -> Path:
    """Train what is not finished, evaluate, write the table; return ``campaign.md``.

    Args:
        campaign: the grid.
        out: its folder (``runs/``, ``results/``, ``status.json``, ``campaign.md``).
        workers: training runs at once (local pool) or in flight (Ray); also the evaluation's.
        executor: ``"local"`` or ``"ray"``.
        address: a Ray cluster address.
        stage: ``"train"``, ``"evaluate"`` (finished runs only) or ``"all"``.
        max_runs: train at most this many unfinished runs now (the rest another time).
        progress: show progress: a line per training iteration and finished run (the runs
            train in worker processes, side by side), the optimal attack's candidates and a
            bar (lines when stderr is a file) for the evaluation.
        only: train only these runs (``METHOD-sSEED``), in this order: how a session picks the
            pieces that fit its time.
        park_every: while training, park the runs trained here every this many seconds
            (`advgame.workflows.park.ParkEvery`; 0: never), so that a process killed without
            ``--park`` loses at most that much of each.

    """
    from advgame.runner.run import run_units

    if stage not in ("train", "evaluate", "all"):
        raise ConfigError(f"stage must be 'train', 'evaluate' or 'all', got {stage!r}.")
    if not park_every >= 0:
        raise ConfigError(f"park_every must be >= 0 seconds, got {park_every}.")
    out = Path(out)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    if stage in ("train", "all"):
        names = campaign.runs() if only is None else list(only)
        unknown = sorted(set(names) - set(campaign.runs()))
        if unknown:
            raise ConfigError(
                f"No run {unknown[0]!r} in the campaign; its runs: {', '.join(campaign.runs())}."
            )
        unfinished = [r for r in names if not (out / FINISHED / r).exists()]
        with claimed(out, unfinished) as mine:
            _left_to_others(out, [r for r in unfinished if r not in mine])
            names = [r for r in names if r in mine or r not in unfinished]
            _unpark(out, names)
            todo = [r for r in names if _progress(run_dir(out, r)) < campaign.config(r).iterations]
            todo = todo[:max_runs] if max_runs is not None else todo
            _check_unchanged(campaign, out, todo)
            release(out, [r for r in mine if r not in todo])  # not trained here now: free them
            write_status(campaign, out, training=todo)
            if todo:
                log.info("campaign: training %d run(s): %s", len(todo), todo)
                show = "lines" if progress else False
                units = [
                    (campaign.config(r), str(out / "runs" / r), str(out / FINISHED / r), show)
                    for r in todo
                ]
                with _parking(campaign, out, todo, park_every):
                    run_units(_train_unit, units, executor=executor, workers=min(workers, len(units)),
                              address=address, max_retries=1,
                              progress=_StatusEach(campaign, out, todo, progress))  # fmt: skip
                _unpark(out, todo)  # the runs that finished drop their parked copies
    status = write_status(campaign, out)
    evaluation_curves(campaign, out)  # the in-training evaluation's figure, if runs have one
    if stage == "train":
        return out / "status.json"
    done = done_runs(status)
    if not done:
        raise ConfigError(f"No finished run in {out / 'runs'} to evaluate; train first.")
    _evaluate(campaign, out, done, workers, executor, address, progress)
    path = campaign_table(campaign, out, out / FINISHED)
    write_status(campaign, out)
    return path


def _parking(campaign: Campaign, out: Path, runs: Sequence[str], seconds: float) -> Any:
    """`ParkEvery` over `runs` every `seconds` (0: a context that does nothing)."""
    import contextlib

    from advgame.workflows.park import ParkEvery

    if not seconds:
        return contextlib.nullcontext()
    return ParkEvery(lambda: park_campaign(campaign, out, only=runs), seconds)


def _left_to_others(out: Path, held: Sequence[str]) -> None:
    """Say which runs another process trains (`advgame.workflows.claims`); they are skipped."""
    from advgame.workflows.claims import describe, holder

    for r in held:
        claim = holder(out, r)
        who = describe(claim) if claim is not None else "another process (it claimed it just now)"
        log.warning(
            "campaign: %s is training in %s; left to it. If that process is not this "
            "campaign's, delete %s and run again.",
            r, who, claim_path(out, r),
        )  # fmt: skip


def _unpark(out: Path, names: Sequence[str]) -> None:
    """Rebuild in ``runs/`` each run whose parked copy is further on (drop finished ones')."""
    import shutil

    from advgame.workflows.park import parked_copies, parked_iteration, unpark_run

    for r in names:
        copies = parked_copies(out, r)
        if (out / FINISHED / r).exists():
            for parked in copies:
                shutil.rmtree(parked, ignore_errors=True)
            continue
        parked = max(copies, key=parked_iteration)  # the first of equals: ADVGAME_PARK's
        if parked_iteration(parked) > _progress(out / "runs" / r):
            log.info("campaign: %s resumes from its parked copy in %s", r, parked)
            unpark_run(parked, out / "runs" / r)


def _check_unchanged(campaign: Campaign, out: Path, names: Sequence[str]) -> None:
    """Refuse to resume a run that the campaign file now configures otherwise.

    A partial run (or its parked copy) resumes from its own ``config.json``; had the file since
    changed what the run learns (a learner's setting, the task), the run would go on under the
    old setting while its table row carries the new. The in-training evaluation's fields may
    change (`advgame.training.conditions.EVAL_FIELDS`: they change nothing learned).
    """
    from dataclasses import fields, replace

    from advgame.core.config import load_json
    from advgame.training.conditions import EVAL_FIELDS
    from advgame.training.config import TrainConfig

    for r in names:
        saved_path = out / "runs" / r / "config.json"
        if not saved_path.is_file():
            continue
        want = campaign.config(r)
        saved = replace(
            load_json(TrainConfig, saved_path), **{f: getattr(want, f) for f in EVAL_FIELDS}
        )
        changed = [
            f.name for f in fields(TrainConfig) if getattr(saved, f.name) != getattr(want, f.name)
        ]
        if changed:
            name = changed[0]
            raise ConfigError(
                f"Run {r} started with {name} = {getattr(saved, name)!r}, but the campaign file now "
                f"gives {getattr(want, name)!r} (changed: {', '.join(changed)}). To train it "
                f"again under the file, move {saved_path.parent} and its parked copies away; to "
                "go on as it started, restore the file."
            )


def park_campaign(
    campaign: Campaign, out: str | Path, only: Sequence[str] | None = None
) -> dict[str, int]:
    """Park every run of the campaign in training (``runs/``, not finished) in ``parked/``.

    Returns the iteration each was parked at. Safe while they train: each is parked at its
    last checkpoint. ``parked/`` stays in the work tree (git ignores it), or with
    ``ADVGAME_PARK`` set the copies go to that folder outside it (`advgame.workflows.park.
    park_root`); the train stage run later resumes each run from its copy. `only`: park just
    these runs (the ones a train stage trains, when it parks them as it goes).
    """
    from advgame.workflows.park import park_root, park_run

    out = Path(out)
    parked = {}
    for r in campaign.runs() if only is None else only:
        run = out / "runs" / r
        if not (out / FINISHED / r).exists() and (run / "state.json").is_file():
            parked[r] = park_run(run, park_root(out) / r)
    return parked


def _evaluate(
    campaign: Campaign,
    out: Path,
    done: Sequence[str],
    workers: int,
    executor: str,
    address: str | None,
    progress: bool,
) -> None:
    """Every finished run's protagonist in one table (finished units are read back)."""
    from advgame.evaluation import use_executor
    from advgame.workflows.suite import evaluate_runs

    with use_executor(executor, address):
        evaluate_runs(
            [run_dir(out, r) for r in done],
            out / "results",
            seeds=campaign.eval_seeds,
            workers=workers,
            exploitability_steps=campaign.exploitability,
            optimal_grid=campaign.search_grid(),
            adversaries=campaign.adversaries,
            threat=campaign.threat,
            budgets=(),
            progress=progress,
            resume=True,
        )
