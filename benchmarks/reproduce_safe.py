"""Reduced-scale reproduction of the paper's safe RL experiment: is PCRPO more robust than CRPO.

The paper (section 4, "robust safe RL") trains CRPO and PCRPO on Safety Walker2d in-training
under action noise or observed-cost noise N(0, 0.15) and N(0, 0.3) and finds that CRPO degrades
while PCRPO stays robust. Here, per seed, algorithm and condition (nominal,
``action-gauss-0.15``, ``action-gauss-0.3``, ``cost-gauss-0.15``, ``cost-gauss-0.3``), one run
of the advgame loop (protagonist only, the preset's Gaussian adversary fixed in training) is
trained, and then measured:

* **in-training** (the paper's curves): mean true return and true episode cost of the training
  episodes of the last quarter of the run (under the training condition);
* **final policy**: the deterministic policy's true return and cost over ``--episodes``
  episodes under the same condition.

The paper's limit and slack are per-step costs (0.04, 5e-3); here they are episode costs:
``0.04·T`` and ``0.005·T`` for episodes of ``T`` steps. Every run is a job in a process pool;
results go to ``<out>/results.json`` and ``<out>/reproduction.md`` (mean ± half-width of a 95 %
Student-t interval over seeds). An interrupted reproduction reuses finished runs.

Run: ``python benchmarks/reproduce_safe.py --seeds 3 --steps 61440 --out
docs/reproduction-safe``.
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np

from advgame.evaluation.table.payoff import ci95

CONDITIONS = (
    "nominal",
    "action-gauss-0.15",
    "action-gauss-0.3",
    "cost-gauss-0.15",
    "cost-gauss-0.3",
)
ALGOS = ("crpo", "pcrpo")
N_STEPS = 2048


def _job(algo: str, condition: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    import torch

    import advgame
    from advgame.core.episodes import rollout
    from advgame.training import TrainConfig
    from advgame.workflows.suite import _train_or_resume, run_protagonist

    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(1)
    preset = "default" if condition == "nominal" else condition
    limit, slack = _limits(args)
    cfg = TrainConfig(
        scenario=args.scenario,
        preset=preset,
        learned=[],
        protagonist_algo=algo,
        protagonist_hparams={
            "n_steps": N_STEPS,
            "cost_limit": limit,
            "slack": slack,
        },
        iterations=max(args.steps // N_STEPS, 1),
        protagonist_steps=N_STEPS,
        adversary_steps=0,
        eval_episodes=0,
        seed=seed,
    )
    run_dir = Path(args.out) / "runs" / f"{algo}-{condition}-s{seed}"
    _train_or_resume(cfg, run_dir)
    with (run_dir / "progress.csv").open() as f:
        rows = list(csv.DictReader(f))
    last = rows[-max(len(rows) // 4, 1) :]
    train_ret = [float(r["protagonist_phase_true_return"]) for r in last]
    train_cost = [float(r["protagonist_phase_true_cost"]) for r in last]
    _, protagonist = run_protagonist(run_dir)
    game = advgame.make(args.scenario, preset=preset, phase="eval")
    fixed = dict(game.preset.adversaries) if condition != "nominal" else {}
    results = rollout(
        game, {**protagonist, **fixed}, seed=50_000 + seed * 100, episodes=args.episodes
    )
    game.close()
    return {
        "algo": algo,
        "condition": condition,
        "seed": seed,
        "train_return": float(np.nanmean(train_ret)),
        "train_cost": float(np.nanmean(train_cost)),
        "eval_return": float(np.mean([r.true_return for r in results])),
        "eval_cost": float(np.mean([r.cost for r in results])),
        "eval_satisfied": float(np.mean([r.cost <= limit for r in results])),
    }


def _limits(args: argparse.Namespace) -> tuple[float, float]:
    """The episode-cost limit and slack: given, or the paper's per-step 0.04 and 5e-3 times T."""
    limit = 0.04 * args.horizon if args.limit is None else args.limit
    slack = 0.005 * args.horizon if args.slack is None else args.slack
    return limit, slack


def _fmt(values: list[float], digits: int = 0) -> str:
    return f"{np.mean(values):.{digits}f} ± {ci95(values):.{digits}f}"


def _markdown(rows: list[dict[str, Any]], args: argparse.Namespace, wall: float) -> str:
    limit, slack = _limits(args)
    lines = [
        f"# Safe RL under attack: CRPO vs PCRPO on {args.scenario} (reduced scale)",
        "",
        f"{args.seeds} seeds, {args.steps} protagonist steps per run (paper: 500 epochs of "
        f"150 000 steps), episodes of at most {args.horizon} steps, cost limit {limit:g} per "
        f"episode, slack {slack:g}. Mean ± half-width of a "
        f"95 % Student-t interval over seeds. Wall time {wall / 60:.0f} min with "
        f"{args.workers} workers.",
        "",
        "| algo | condition | in-training return | in-training cost | final return | "
        "final cost | final cost ≤ limit |",
        "|---|---|---|---|---|---|---|",
    ]
    for algo in ALGOS:
        for cond in args.conditions:
            sel = [r for r in rows if r["algo"] == algo and r["condition"] == cond]
            if not sel:
                continue

            def col(key: str, digits: int = 0, sel: list = sel) -> str:
                return _fmt([r[key] for r in sel], digits)

            lines.append(
                f"| {algo} | {cond} | {col('train_return')} | {col('train_cost', 1)} | "
                f"{col('eval_return')} | {col('eval_cost', 1)} | {col('eval_satisfied', 2)} |"
            )
    lines += ["", "Change of the in-training return from nominal (same seed), per algorithm:", ""]
    lines += ["| condition | CRPO | PCRPO |", "|---|---|---|"]
    for cond in [c for c in args.conditions if c != "nominal"]:
        cells = []
        for algo in ALGOS:
            nominal = {
                r["seed"]: r["train_return"]
                for r in rows
                if r["algo"] == algo and r["condition"] == "nominal"
            }
            diffs = [
                r["train_return"] - nominal[r["seed"]]
                for r in rows
                if r["algo"] == algo and r["condition"] == cond and r["seed"] in nominal
            ]
            cells.append(_fmt(diffs) if diffs else "-")
        lines.append(f"| {cond} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    """Train every (algorithm, condition, seed) run in a pool; write the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="SafetyWalker2d-v5")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=61_440, help="protagonist steps per run")
    parser.add_argument("--horizon", type=int, default=1000, help="the task's episode length")
    parser.add_argument("--episodes", type=int, default=5, help="final-policy episodes per run")
    parser.add_argument(
        "--limit", type=float, help="episode-cost limit (default: the paper's 0.04 per step × T)"
    )
    parser.add_argument("--slack", type=float, help="slack (default: the paper's 5e-3 × T)")
    parser.add_argument("--conditions", nargs="+", choices=CONDITIONS, default=list(CONDITIONS))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="docs/reproduction-safe")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(a, c, s) for s in range(args.seeds) for a in ALGOS for c in args.conditions]
    start = time.perf_counter()
    with ProcessPoolExecutor(args.workers, mp_context=get_context("forkserver")) as pool:
        rows = list(pool.map(_job, *zip(*jobs, strict=True), [args] * len(jobs)))
    wall = time.perf_counter() - start
    (out / "results.json").write_text(json.dumps(rows, indent=1) + "\n")
    (out / "reproduction.md").write_text(_markdown(rows, args, wall))
    print((out / "reproduction.md").read_text())


if __name__ == "__main__":
    main()
