"""Ready-made workflows: evaluate fixed policies against chosen adversaries, rebuild reports.

`evaluate_policies` plays any protagonists (run finals, SB3 models trained elsewhere, teams,
callables) against adversary columns named by specs (`advgame.evaluation.table.columns`: by default the nominal
task, the paper's random attacks, a scheduled shift and every run's latest learned
adversaries), with a budget sweep, and writes a results folder that stands on its own (run
paths relative to it, training curves copied in) with a Markdown report. `evaluate_runs` is
what ``advgame evaluate`` runs on top of it; `report_folder` rebuilds a folder's report. The
demo (`advgame.workflows.demo`) trains PPO and ATLA-PPO briefly and evaluates them this way.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from advgame.errors import ConfigError
from advgame.evaluation import (
    AdversarySetup,
    PayoffTable,
    budget_sweep,
    evaluate,
)
from advgame.evaluation.attacks.optimal import (
    OPTIMAL,
    OptimalSearch,
    optimal_jobs,
    optimal_search,
    released_jobs,
    write_exploitability,
)
from advgame.evaluation.table.columns import (
    RANDOM,
    SCHEDULED,
    default_threat,
    describe_column,
    observation_agent,
)
from advgame.evaluation.table.protagonists import (
    check_protagonists,
    cli_protagonists,
    run_protagonist,
)
from advgame.evaluation.table.stored import adopt_earlier_table
from advgame.workflows.cells import table_jobs

__all__ = [
    "BUDGETS",
    "RANDOM",
    "SCHEDULED",
    "evaluate_policies",
    "evaluate_runs",
    "report_folder",
    "run_protagonist",
]

log = logging.getLogger(__name__)
BUDGETS = (0.0, 0.05, 0.1, 0.15)
"""Gaussian state-noise σ of the return-vs-budget sweep (the paper's Fig. 3 levels and more)."""


def evaluate_policies(
    scenario: str,
    protagonists: Mapping[str, Any],
    out: str | Path,
    *,
    adversaries: Sequence[str] | Mapping[str, AdversarySetup] = ("default",),
    runs: Mapping[str, str | Path] | None = None,
    last: int | None = None,
    sample: int | None = None,
    seed: int = 0,
    seeds: int = 3,
    episodes: int = 1,
    workers: int = 2,
    budgets: Sequence[float] = BUDGETS,
    progress: bool = True,
    threat: str | None = None,
    optimal: OptimalSearch | None = None,
    resume: bool = False,
    released: Mapping[str, Any] | None = None,
) -> Path:
    """Evaluate fixed policies against chosen adversary columns; write the folder, return ``report.md``.

    Args:
        scenario: the registered scenario every cell plays.
        protagonists: ``{name: spec}`` (`sb3_protagonist`, `team_protagonist`, a callable...).
        out: the results folder (``payoff.csv``, ``columns.json``, ``runs.json``, plots, report).
        adversaries: column specs (`advgame.evaluation.table.columns.adversary_columns`) or ready setups.
        runs: ``{name: run directory}`` whose training curves (and, for ``learned``/``default``,
            adversaries) join the report; their progress CSVs are copied into `out`.
        last: keep the last K snapshots of population columns that do not say otherwise.
        sample: or K snapshots drawn from each (with `seed`).
        seed: seeds the drawing of ``sample``.
        seeds: evaluation seeds per cell (0 .. seeds-1).
        episodes: episodes per seed.
        workers: evaluation processes.
        budgets: σ levels of the state-noise sweep (empty: no sweep).
        progress: show progress bars.
        threat: the table's one threat model, a preset of `scenario` that attack, learned and
            best-response columns all play in (default `advgame.evaluation.table.columns.default_threat`);
            ``threat.json`` and the report's section only where some column plays in it.
        optimal: search the learned optimal attack for every protagonist
            (`advgame.evaluation.attacks.optimal`): the ``attack optimal`` column, and the
            exploitability (nominal minus its return) in ``exploitability.json`` and the report.
        resume: keep each finished unit of the table as a part file in ``out/parts`` and read
            it back instead of playing it again (for folders whose protagonists never change,
            such as a campaign's finished runs).
        released: ``{protagonist: adversary spec}``: the ``attack optimal`` column from
            adversaries found before (those released with zoo agents), each row playing its
            own, instead of a search (`optimal`).

    """
    out = Path(out)
    run_dirs = {n: Path(d) for n, d in (runs or {}).items()}
    if not protagonists:
        raise ConfigError("Nothing to evaluate: give run directories, checkpoints or callables.")
    check_protagonists(scenario, protagonists)
    columns, jobs = table_jobs(scenario, protagonists, adversaries, runs=run_dirs, last=last,
                               sample=sample, seed=seed, seeds=seeds, episodes=episodes,
                               threat=threat)  # fmt: skip
    seed_list = tuple(range(seeds))
    out.mkdir(parents=True, exist_ok=True)
    threat = threat or default_threat(scenario)
    if optimal is not None and released is not None:
        raise ConfigError("Search the optimal attack or play released adversaries, not both.")
    learned_column = optimal is not None or released is not None
    agent = observation_agent(scenario, threat) if learned_column else ""
    if optimal is not None:
        jobs += optimal_jobs(scenario, threat, agent, protagonists, optimal, out, seeds=seed_list,
                             episodes=episodes, progress=progress)  # fmt: skip
    if released is not None:
        jobs += released_jobs(scenario, threat, agent, protagonists, released, seeds=seed_list,
                              episodes=episodes)  # fmt: skip
    if resume:
        adopt_earlier_table(jobs, out)
    table = evaluate(jobs, workers=workers, progress=progress, results_dir=out if resume else None)
    table.to_csv(out / "payoff.csv")
    if optimal is not None:
        write_exploitability(out, table, threat, optimal.steps)
    if budgets:
        sweep = budget_sweep(scenario, protagonists, budgets, seeds=seed_list, episodes=episodes)
        evaluate(sweep, workers=workers, progress=progress).to_csv(out / "budget.csv")
    else:
        (out / "budget.csv").unlink(missing_ok=True)
    columns_json = {n: describe_column(s) for n, s in columns.items()}
    if optimal is not None:
        searched = f"learned PPO adversaries, the strongest of {len(optimal.grid)} per protagonist"
        columns_json[OPTIMAL] = {
            "game": {"preset": threat},
            "adversaries": {agent: f"{searched} ({optimal.steps} steps each; optimal.json)"},
        }
    if released is not None:
        columns_json[OPTIMAL] = {
            "game": {"preset": threat},
            "adversaries": {agent: "each protagonist's own learned adversary, as released"},
        }
    (out / "columns.json").write_text(json.dumps(columns_json, indent=2, default=str) + "\n")
    record = _threat_record(scenario, threat)  # checks the name whether or not a column plays it
    if any(c["game"].get("preset") == threat for c in columns_json.values()):
        (out / "threat.json").write_text(json.dumps(record, indent=2) + "\n")
    else:  # no column plays in it (presets only): the report names no threat model
        (out / "threat.json").unlink(missing_ok=True)
    _write_runs(out, run_dirs)
    return report_folder(out, scenario=scenario)


def _threat_record(scenario: str, preset: str) -> dict[str, Any]:
    """What the threat model is, for ``threat.json`` and the report."""
    from advgame.core.registry import scenario_spec

    presets = scenario_spec(scenario).load_presets()
    if preset not in presets:
        raise ConfigError(f"The threat model must be a preset of {scenario}: {sorted(presets)}.")
    return {
        "preset": preset,
        "description": presets[preset].description,
        "disruptors": [repr(d) for d in presets[preset].disruptors],
    }


def _threat_md(record: Mapping[str, Any]) -> str:
    lines = [
        f"Preset `{record['preset']}` ({record['description']}). Attack columns, learned "
        "columns and best responses all play in it, whatever preset each protagonist was "
        "trained in, so every row faces the same disruptors and budgets (learned adversaries "
        "that cannot act in it play in their training preset: see each column's game under Adversary columns):",
        "",
    ]
    return "\n".join(lines + [f"- `{d}`" for d in record["disruptors"]])


def _write_runs(out: Path, runs: Mapping[str, Path]) -> None:
    """``runs.json``: each run's path relative to `out`, its progress CSV copied into `out`."""
    from advgame.reports.report import runs_cost_limit

    entries: dict[str, dict[str, Any]] = {}
    for name, run_dir in runs.items():
        entry: dict[str, Any] = {"path": _relpath(run_dir, out)}
        limit = runs_cost_limit([run_dir])
        if limit is not None:  # a constrained learner's limit: the report's safety section
            entry["cost_limit"] = limit
        if (run_dir / "progress.csv").is_file():
            copy = out / "progress" / f"{name}.csv"
            copy.parent.mkdir(exist_ok=True)
            shutil.copyfile(run_dir / "progress.csv", copy)
            entry["progress"] = copy.relative_to(out).as_posix()
        entries[name] = entry
    (out / "runs.json").write_text(json.dumps(entries, indent=2) + "\n")


def _relpath(path: Path, start: Path) -> str:
    try:
        return Path(os.path.relpath(path.resolve(), start.resolve())).as_posix()
    except ValueError:  # another drive (Windows)
        return path.resolve().as_posix()


def _read_runs(folder: Path) -> dict[str, dict[str, str]]:
    """``runs.json`` of `folder`; old files (``{name: path}``, relative to the cwd) as well."""
    path = folder / "runs.json"
    runs = json.loads(path.read_text()) if path.exists() else {}
    return {n: {"path": e} if isinstance(e, str) else dict(e) for n, e in runs.items()}


def _progress_path(folder: Path, entry: Mapping[str, str]) -> Path:
    """A run's progress CSV: the copy in `folder`, else the run's own.

    The run's path is tried relative to `folder`, then to the current directory (as folders
    written before copies stored it).
    """
    if entry.get("progress") and (folder / entry["progress"]).is_file():
        return folder / entry["progress"]
    if (folder / entry["path"] / "progress.csv").is_file():
        return folder / entry["path"] / "progress.csv"
    return Path(entry["path"]) / "progress.csv"


def _runs_md(runs: Mapping[str, Mapping[str, str]]) -> str:
    lines = [
        f"- `{n}`: run `{e['path']}`"
        + (f", training curves from [{e['progress']}]({e['progress']})" if "progress" in e else "")
        for n, e in runs.items()
    ]
    note = "Run paths are relative to this folder; training curves link to copies in it."
    return "\n".join(lines) + "\n\n" + note if lines else "none"


def evaluate_runs(
    runs: Sequence[str | Path],
    out: Path,
    *,
    seeds: int = 3,
    episodes: int = 1,
    workers: int = 2,
    exploitability_steps: int = 0,
    checkpoints: Sequence[str] = (),
    callables: Sequence[str] = (),
    scenario: str | None = None,
    normalizers: Sequence[str] = (),
    raw_obs: Sequence[str] = (),
    teams: Sequence[str] = (),
    adversaries: Sequence[str] = ("default",),
    last: int | None = None,
    sample: int | None = None,
    seed: int = 0,
    budgets: Sequence[float] = BUDGETS,
    progress: bool = True,
    threat: str | None = None,
    resume: bool = False,
    released: Mapping[str, tuple[str, Any]] | None = None,
    released_adversaries: Mapping[str, Any] | None = None,
    optimal_grid: Sequence[Mapping[str, Any]] | None = None,
) -> Path:
    """What ``advgame evaluate`` runs, through `evaluate_policies`; return ``report.md``.

    The protagonists are the runs' final ones, `released` agents (``{name: (scenario,
    spec)}``: what `advgame.workflows.zoo.evaluation_inputs` gives for ids such as
    ``hopper/ppo``) and fixed policies given as ``NAME=...`` strings (`cli_protagonists`); the
    scenario is `scenario`, the runs' or the released agents'. `released_adversaries`
    (``{name: adversary spec}``) adds the ``attack optimal`` column played by each released
    agent's own adversary (only released agents then). `optimal_grid` replaces the searched
    optimal attack's grid (`OptimalSearch.grid`; None: `OPTIMAL_GRID`).
    """
    released = dict(released or {})
    found = {Path(r).name: (run_protagonist(Path(r)), Path(r)) for r in runs}
    if released_adversaries is not None and (runs or checkpoints or callables or teams):
        raise ConfigError(
            "--zoo-adversaries plays each zoo agent's own adversary: evaluate the zoo agents "
            "apart from runs, checkpoints and callables."
        )
    scenarios = {str(cfg.scenario) for (cfg, _), _ in found.values()}
    scenarios |= {s for s, _ in released.values()}
    scenarios |= {scenario} if scenario else set()
    if len(scenarios) > 1:
        raise ConfigError(
            f"The runs and --scenario name different scenarios {sorted(scenarios)}; "
            "evaluate them apart."
        )
    if not scenarios:
        raise ConfigError("Give --scenario ID or a run directory (its scenario is evaluated).")
    sid = str(scenarios.pop())
    protagonists: dict[str, Any] = {n: spec for n, ((_, spec), _) in found.items()}
    protagonists.update({z: spec for z, (_, spec) in released.items()})
    extra = cli_protagonists(
        sid, checkpoints=checkpoints, normalizers=normalizers, raw_obs=raw_obs,
        callables=callables, teams=teams,
    )  # fmt: skip
    clash = sorted(set(extra) & set(protagonists))
    if clash:
        raise ConfigError(f"Protagonist names {clash} are taken by runs; name them apart.")
    protagonists.update(extra)
    search = optimal_search(exploitability_steps, optimal_grid, workers=workers)
    return evaluate_policies(
        sid, protagonists, out, adversaries=adversaries, runs={n: d for n, (_, d) in found.items()},
        last=last, sample=sample, seed=seed, seeds=seeds, episodes=episodes, workers=workers,
        budgets=budgets, progress=progress, threat=threat, optimal=search, resume=resume,
        released=released_adversaries,
    )  # fmt: skip


def report_folder(folder: Path, scenario: str | None = None) -> Path:
    """(Re)build ``report.md`` and its plots from the files an evaluation wrote in `folder`."""
    from advgame.reports.report import (
        adversary_listing,
        exploitability_md,
        plot_budget_curve,
        plot_training_curves,
        write_report,
    )

    if not (folder / "payoff.csv").exists():
        raise ConfigError(
            f"{folder} has no payoff.csv; run `advgame evaluate ... --out {folder}` first."
        )
    table = PayoffTable.from_csv(folder / "payoff.csv")
    figures: dict[str, Path] = {}
    if (folder / "budget.csv").exists():
        figures["true return vs Gaussian state-noise σ"] = plot_budget_curve(
            PayoffTable.from_csv(folder / "budget.csv"), folder / "budget.png"
        )
    runs = _read_runs(folder)
    csvs = {n: _progress_path(folder, e) for n, e in runs.items()}
    curves = plot_training_curves(csvs, folder / "training.png") if csvs else None
    if curves is not None:
        figures["training curves"] = curves
    sections = {"Runs": _runs_md(runs)}
    if (folder / "threat.json").exists():
        sections["Threat model"] = _threat_md(json.loads((folder / "threat.json").read_text()))
    if (folder / "columns.json").exists():
        sections["Adversary columns"] = adversary_listing(
            json.loads((folder / "columns.json").read_text())
        )
    if (folder / "exploitability.json").exists():
        sections["Exploitability"] = exploitability_md(
            json.loads((folder / "exploitability.json").read_text())
        )
    title = f"advgame robustness report: {scenario or table.rows[0].get('scenario', '')}".rstrip(
        ": "
    )
    return write_report(
        folder, title, table, extra_sections=sections, figures=figures, cost_limit=_cost_limit(runs)
    )


def _cost_limit(runs: Mapping[str, Mapping[str, Any]]) -> float | None:
    """The smallest cost limit the runs' constrained learners trained with, or None.

    `_write_runs` records each run's limit in ``runs.json``, so a moved folder keeps it.
    """
    limits = [float(e["cost_limit"]) for e in runs.values() if "cost_limit" in e]
    return min(limits) if limits else None
