"""Ready-made workflows: evaluate trained runs against an adversary population, and the demo.

`evaluate_runs` is what ``advgame evaluate`` runs: the final protagonist of each run (plus any
checkpoints or plain functions) against the nominal task, the paper's random attacks, a
scheduled shift, and every run's learned adversaries, with a budget sweep, training curves,
optional exploitability, and a Markdown report. `demo` trains PPO and ATLA-PPO briefly on
Hopper-v5 and evaluates them the same way.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from advgame.checkpoint import SB3Checkpoint
from advgame.config import load_json
from advgame.errors import ConfigError
from advgame.evaluation import AdversarySetup, PayoffTable, budget_sweep, evaluate, population_jobs
from advgame.population import Population
from advgame.registry import load, make, scenario_spec
from advgame.training import TEAM_ALGOS, TrainConfig

__all__ = ["BUDGETS", "demo", "evaluate_runs", "report_folder", "run_protagonist"]

log = logging.getLogger(__name__)

_ACTOR_SPEC = "advgame.agents.marl_nets:TorchActorCheckpoint"

RANDOM = ("state-gauss-0.1", "state-gauss-0.15", "state-uniform-0.2-0.8", "action-gauss-0.1")
"""Random-mode presets evaluated when the scenario has them (the paper's settings)."""
SAFE_RANDOM = ("action-gauss-0.15", "action-gauss-0.3", "cost-gauss-0.15", "cost-gauss-0.3")
"""The paper's safe-RL settings, evaluated on safe scenarios (action and observed-cost noise)."""
SCHEDULED = ("shift-sinusoid", "state-gauss-0.1-100F")
"""The first of these the scenario has is its scheduled column."""
SCHEDULE_EPISODES = 8
"""Consecutive episodes per seed in the scheduled column (the sinusoid advances per episode)."""
BUDGETS = (0.0, 0.05, 0.1, 0.15)
"""Gaussian state-noise σ of the return-vs-budget sweep (the paper's Fig. 3 levels and more)."""


def run_protagonist(run_dir: Path) -> tuple[TrainConfig, Any]:
    """A finished (or interrupted) run's config and its last protagonist(s) as a policy spec.

    Team runs (MAPPO/IPPO) give ``{protagonist id: spec}``, one actor per protagonist.
    """
    state_path = run_dir / "state.json"
    if not state_path.exists():
        raise ConfigError(
            f"{run_dir} has no finished iteration (no state.json); train or resume it."
        )
    cfg = load_json(TrainConfig, run_dir / "config.json")
    folder = run_dir / json.loads(state_path.read_text())["checkpoint"]
    if cfg.protagonist_algo in TEAM_ALGOS:
        actor = load(_ACTOR_SPEC)
        path = str(folder / f"{cfg.protagonist_algo}_actors.pt")
        protagonists = make(cfg.scenario, preset=cfg.preset).protagonists
        return cfg, {p: actor(path, p, deterministic=True) for p in protagonists}
    norm = folder / "protagonist_obs_norm.npz"
    spec = SB3Checkpoint(
        str(folder / "protagonist.zip"),
        cfg.protagonist_algo,
        str(norm) if norm.exists() else None,
        deterministic=True,
    )
    return cfg, spec


def _adversary_columns(
    scenario: str, runs: dict[str, tuple[TrainConfig, Path]]
) -> dict[str, AdversarySetup]:
    presets = scenario_spec(scenario).load_presets()
    cols: dict[str, AdversarySetup] = {"nominal": AdversarySetup.nominal()}
    for name in RANDOM:
        if name in presets:
            cols[f"random {name}"] = AdversarySetup.from_preset(scenario, name)
    for name in SAFE_RANDOM if scenario_spec(scenario).family == "safe" else ():
        if name in presets:
            cols[f"random {name}"] = AdversarySetup.from_preset(scenario, name)
    for name in SCHEDULED:
        if name in presets:
            cols[f"scheduled {name}"] = AdversarySetup.from_preset(scenario, name)
            break
    for run, (cfg, run_dir) in runs.items():
        pop = (
            Population.load(run_dir / "population.json")
            if (run_dir / "population.json").exists()
            else Population()
        )
        learned = {m.agent: m for m in pop if m.learned}  # the latest snapshot of each agent
        if learned:
            specs = {a: replace(m.spec, deterministic=True) for a, m in learned.items()}
            cols[f"learned ({run})"] = AdversarySetup({"preset": cfg.preset}, specs)
    return cols


def _extra_protagonists(checkpoints: Sequence[str], callables: Sequence[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in checkpoints:
        name, _, rest = item.partition("=")
        path, _, algo = rest.partition(":")
        if not name or not path:
            raise ConfigError(f"--checkpoint takes NAME=PATH[:ALGO], got {item!r}.")
        out[name] = SB3Checkpoint(path, algo or "ppo", deterministic=True)
    for item in callables:
        name, _, target = item.partition("=")
        if not name or ":" not in target:
            raise ConfigError(f"--callable takes NAME=MODULE:FUNCTION, got {item!r}.")
        out[name] = load(target)
    return out


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
    progress: bool = True,
) -> Path:
    """Evaluate runs' protagonists (and extra ones) against a population; return ``report.md``."""
    found = {Path(r).name: (run_protagonist(Path(r)), Path(r)) for r in runs}
    protagonists: dict[str, Any] = {n: spec for n, ((_, spec), _) in found.items()}
    protagonists.update(_extra_protagonists(checkpoints, callables))
    if not protagonists:
        raise ConfigError("Nothing to evaluate: give run directories, --checkpoint or --callable.")
    scenarios = {cfg.scenario for (cfg, _), _ in found.values()}
    if len(scenarios) > 1:
        raise ConfigError(
            f"The runs are of different scenarios {sorted(scenarios)}; evaluate them apart."
        )
    if not scenarios:
        raise ConfigError("Give at least one run directory (its scenario is evaluated).")
    scenario = scenarios.pop()
    columns = _adversary_columns(scenario, {n: (cfg, d) for n, ((cfg, _), d) in found.items()})
    seed_list = tuple(range(seeds))
    jobs = population_jobs(scenario, protagonists, columns, seeds=seed_list, episodes=episodes)
    # A per-episode schedule needs several consecutive episodes per seed to move at all.
    jobs = [
        replace(j, episodes=max(episodes, SCHEDULE_EPISODES))
        if j.adversary.startswith("scheduled")
        else j
        for j in jobs
    ]
    table = evaluate(
        jobs,
        workers=workers,
        progress=progress,
    )
    sweep = evaluate(
        budget_sweep(scenario, protagonists, BUDGETS, seeds=seed_list, episodes=episodes),
        workers=workers,
        progress=progress,
    )
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / "payoff.csv")
    sweep.to_csv(out / "budget.csv")
    (out / "runs.json").write_text(json.dumps({n: str(d) for n, (_, d) in found.items()}, indent=2))
    if exploitability_steps:
        _exploitability(scenario, found, out, exploitability_steps, episodes * seeds)
    return report_folder(out, scenario=scenario)


def _exploitability(scenario: str, found: dict, out: Path, steps: int, episodes: int) -> None:
    from advgame.exploit import exploitability

    results = {}
    for name, ((cfg, spec), _) in found.items():
        preset = cfg.preset if cfg.learned != [] else "default"
        results[name] = {
            "preset": preset,
            **exploitability(
                scenario, preset, spec, out / "best_response" / name, steps=steps, episodes=episodes
            ),
        }
    (out / "exploitability.json").write_text(json.dumps(results, indent=2))


def report_folder(folder: Path, scenario: str | None = None) -> Path:
    """(Re)build ``report.md`` and its plots from the files an evaluation wrote in `folder`."""
    from advgame.report import plot_budget_curve, plot_training_curves, write_report

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
    runs = json.loads((folder / "runs.json").read_text()) if (folder / "runs.json").exists() else {}
    curves = plot_training_curves(
        {n: Path(d) / "progress.csv" for n, d in runs.items()}, folder / "training.png"
    )
    if curves is not None:
        figures["training curves"] = curves
    sections = {"Runs": "\n".join(f"- `{n}`: `{d}`" for n, d in runs.items()) or "none"}
    if (folder / "exploitability.json").exists():
        sections["Exploitability"] = _exploit_md(
            json.loads((folder / "exploitability.json").read_text())
        )
    title = f"advgame robustness report: {scenario or table.rows[0].get('scenario', '')}".rstrip(
        ": "
    )
    from advgame.report import runs_cost_limit

    limit = runs_cost_limit(runs.values())
    return write_report(
        folder, title, table, extra_sections=sections, figures=figures, cost_limit=limit
    )


def _exploit_md(results: dict[str, dict[str, Any]]) -> str:
    lines = [
        "Return under best-response adversaries trained against each frozen protagonist "
        "within the preset's budget (an upper bound on the worst case).",
        "",
        "| protagonist | preset | nominal | best response | exploitability | steps |",
        "|---|---|---|---|---|---|",
    ]
    for name, r in results.items():
        lines.append(
            f"| {name} | {r['preset']} | {r['nominal_return']:.4g} | "
            f"{r['best_response_return']:.4g} | {r['exploitability']:.4g} | "
            f"{int(r['best_response_steps'])} |"
        )
    return "\n".join(lines)


def _train_or_resume(cfg: TrainConfig, run_dir: Path) -> None:
    from advgame.training import resume, train

    if (run_dir / "state.json").exists():
        state = json.loads((run_dir / "state.json").read_text())
        if state["iteration"] >= cfg.iterations:
            log.info("%s is complete; reusing it", run_dir)
            return
        resume(run_dir)
    elif (run_dir / "config.json").exists():
        resume(run_dir)
    else:
        train(cfg, run_dir)


def demo(out: Path, quick: bool = False, workers: int = 2) -> Path:
    """Train PPO and ATLA-PPO on Hopper-v5 briefly, evaluate both, write the report.

    Interrupted demos pick up where they stopped (finished runs are reused). `quick` shrinks
    everything to a smoke test.
    """
    from advgame.training import METHODS

    if quick:
        sizes: dict[str, Any] = {
            "iterations": 2,
            "protagonist_steps": 256,
            "adversary_steps": 256,
            "protagonist_hparams": {"n_steps": 128},
            "adversary_hparams": {"n_steps": 128},
            "eval_episodes": 1,
        }
    else:
        sizes = {
            "iterations": 8,
            "protagonist_steps": 2048,
            "adversary_steps": 1024,
            "adversary_hparams": {"n_steps": 1024},
            "eval_episodes": 2,
        }
    runs = []
    for method in ("ppo", "atla"):
        cfg = TrainConfig(scenario="Hopper-v5", seed=0, **{**sizes, **METHODS[method]})
        run_dir = out / "runs" / method
        _train_or_resume(cfg, run_dir)
        runs.append(run_dir)
    return evaluate_runs(runs, out, seeds=2 if quick else 3, episodes=1, workers=workers)
