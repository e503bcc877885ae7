"""How strong are the attacks? PPO and ATLA-PPO under random, white-box and learned attacks.

Per seed: PPO and ATLA-PPO trained with the project's loop (same protagonist steps; ATLA adds as
many adversary steps), then each evaluated in ONE threat model — ATLA's L∞ observation budget
in the protagonist's normalized units (preset ``atla``; Hopper ε = 0.075) — against: nothing
(nominal), uniform noise filling the budget (`RandomAdversary`), MAD and the critic attack
(`advgame.adversaries.whitebox`, 10 steps, default step size), and a learned best response
trained against the frozen protagonist in the same budget. The worst column per protagonist is
what a robust evaluation reports. Attack cost is the wall time per protagonist step of an
episode under the attack, beside the nominal episode's.

Results: ``<out>/results.json`` and ``<out>/attacks.md`` (mean ± 95 % Student-t interval over
seed means). Run: ``python benchmarks/attack_strength.py --seeds 3 --steps 20480 --out
docs/attacks/hopper`` (about 25 minutes on 2 busy cores); for a task without ATLA's budgets,
name the threat model, e.g. ``--scenario InvertedPendulum-v5 --preset obs-normalized-0.1``.

``--zoo ID`` measures the searched optimal attack against an outside yardstick instead (issue
36): on the released agent ID, side by side in one run, advgame's search (`OptimalSearch`:
``--grid`` entries of `OPTIMAL_GRID`, ``--br-steps`` each, selected on ``--select-seeds``) and
a plain SB3 PPO adversary written without advgame (`outside_adversary.py`, ``--br-steps`` as
well); both are then played in one advgame table (``--episodes`` seeds, both sides
deterministic) beside nominal, and the outside adversary once more in its own env as a check
that advgame plays it as written. ``<out>/strength.md`` holds the table with the machine's
calibration; e.g. ``python benchmarks/attack_strength.py --zoo hopper/ppo --br-steps 200000
--grid 4,5,6,7 --episodes 10 --out docs/attacks/strength-hopper``.
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
from _common import fmt

COLUMNS = ("nominal", "random", "MAD", "critic", "learned")


def _train(seed: int, args: argparse.Namespace) -> dict[str, Path]:
    from advgame.training import METHODS, TrainConfig
    from advgame.workflows.suite import _train_or_resume

    common = {
        "scenario": args.scenario,
        "seed": seed,
        "iterations": max(args.steps // 2048, 1),
        "protagonist_steps": 2048,
        "adversary_steps": 2048,
        "eval_episodes": 1,
    }
    dirs = {}
    for method in ("ppo", "atla"):
        run_dir = Path(args.out) / "runs" / f"{method}-s{seed}"
        fields = {**common, **METHODS[method]}
        if method == "atla":  # ATLA trains against a learned attack in the table's threat model
            fields["preset"] = args.preset
        _train_or_resume(TrainConfig(**fields), run_dir)
        dirs[method] = run_dir
    return dirs


def _play(args: argparse.Namespace, protagonist: Any, adversary: Any, seed: int) -> tuple:
    """Mean true return over the episodes, and wall ms per protagonist step."""
    import advgame
    from advgame.core.episodes import rollout

    game = advgame.make(args.scenario, preset=args.preset, phase="eval")
    policies = {"protagonist": protagonist}
    if adversary is not None:
        policies["observation_adversary"] = adversary
    start = time.perf_counter()
    results = rollout(game, policies, seed=10_000 + 100 * seed, episodes=args.episodes)
    elapsed = time.perf_counter() - start
    game.close()
    steps = sum(r.length for r in results)
    return float(np.mean([r.true_return for r in results])), 1000 * elapsed / max(steps, 1)


def _seed_job(seed: int, args: argparse.Namespace) -> dict[str, float]:
    import torch

    from advgame.adversaries import CriticAttack, MADAttack, RandomAdversary
    from advgame.evaluation.attacks.exploit import best_responses
    from advgame.workflows.suite import run_protagonist

    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(1)
    row: dict[str, float] = {}
    for method, run_dir in _train(seed, args).items():
        protagonist = run_protagonist(run_dir)[1]
        learned = best_responses(
            args.scenario,
            args.preset,
            protagonist,
            Path(args.out) / "br" / f"{method}-s{seed}",
            steps=args.br_steps,
            seed=seed,
        )["observation_adversary"]
        attacks = {
            "nominal": None,
            "random": RandomAdversary(),
            "MAD": MADAttack(),
            "critic": CriticAttack(),
            "learned": learned,
        }
        for column, adversary in attacks.items():
            mean, ms = _play(args, protagonist, adversary, seed)
            row[f"{method} {column}"], row[f"{method} {column} ms"] = mean, ms
    return row


def _markdown(rows: list[dict[str, float]], args: argparse.Namespace) -> str:
    lines = [
        f"# Attack strength on {args.scenario}: PPO and ATLA-PPO in one threat model",
        "",
        f"Measured with `python benchmarks/attack_strength.py --scenario {args.scenario} "
        f"--preset {args.preset} --seeds {args.seeds} --steps {args.steps} --br-steps "
        f"{args.br_steps} --episodes {args.episodes}` on 2 CPU cores shared with other jobs: "
        f"{args.seeds} seeds, {args.steps} protagonist steps per run (ATLA adds as many "
        f"adversary steps), best responses trained {args.br_steps} steps, {args.episodes} "
        "evaluation episodes per seed and column. Mean true return ± half-width of a 95 % "
        "Student-t interval over seed means; every column is the same budget (the preset's).",
        "",
        "| protagonist | " + " | ".join(COLUMNS) + " | worst |",
        "|---" * (len(COLUMNS) + 2) + "|",
    ]
    for method in ("ppo", "atla"):
        cells = [fmt([r[f"{method} {c}"] for r in rows]) for c in COLUMNS]
        attacked = [c for c in COLUMNS if c != "nominal"]
        means = {c: float(np.mean([r[f"{method} {c}"] for r in rows])) for c in attacked}
        worst = min(means, key=means.__getitem__)
        lines.append(f"| {method} | " + " | ".join(cells) + f" | {worst} |")
    lines += ["", "Attack cost, ms per protagonist step (mean over seeds):", ""]
    lines += ["| protagonist | " + " | ".join(COLUMNS) + " |", "|---" * (len(COLUMNS) + 1) + "|"]
    for method in ("ppo", "atla"):
        ms = [f"{np.mean([r[f'{method} {c} ms'] for r in rows]):.2f}" for c in COLUMNS]
        lines.append(f"| {method} | " + " | ".join(ms) + " |")
    return "\n".join(lines) + "\n"


def _outside(args: argparse.Namespace, victim: Any, eps: float) -> dict[str, Any]:
    """Train the outside adversary (no advgame in its code) and play it in its own env."""
    import outside_adversary

    seeds = list(range(20_000, 20_000 + args.episodes))
    start = time.perf_counter()
    files = outside_adversary.train(args.scenario, victim.path, victim.normalizer, eps,
                                    args.br_steps, 0, Path(args.out) / "outside")  # fmt: skip
    took = time.perf_counter() - start
    own = outside_adversary.evaluate(
        args.scenario, victim.path, victim.normalizer, eps, files, seeds
    )
    return {"files": files, "own_returns": own, "train_s": took}


def _strength(args: argparse.Namespace) -> None:
    """Issue 36: advgame's searched optimal attack beside an outside SB3 adversary, one table."""
    from calibrate import step_us

    from advgame.agents.common.checkpoint import SB3Checkpoint
    from advgame.core.registry import scenario_spec
    from advgame.evaluation import AdversarySetup, evaluate, population_jobs
    from advgame.evaluation.attacks.optimal import OPTIMAL_GRID, OptimalSearch, optimal_jobs
    from advgame.evaluation.table.threat import observation_agent
    from advgame.workflows import zoo

    entry, victim = zoo.entry(args.zoo), zoo.load(args.zoo)
    args.scenario, args.preset = entry.scenario, entry.threat
    agent = observation_agent(args.scenario, args.preset)
    (disruptor,) = [d for d in scenario_spec(args.scenario).load_presets()[args.preset].disruptors
                    if d.agent == agent]  # fmt: skip
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    before = f"{step_us(repeats=3):.1f} µs per raw HalfCheetah-v5 step"
    grid = tuple(OPTIMAL_GRID[int(k)] for k in args.grid.split(",")) if args.grid else OPTIMAL_GRID
    search = OptimalSearch(steps=args.br_steps, grid=grid, select_seeds=args.select_seeds,
                           workers=max(args.workers - 1, 1))  # fmt: skip
    seeds = list(range(20_000, 20_000 + args.episodes))
    with ProcessPoolExecutor(1, mp_context=get_context("forkserver")) as pool:
        outside = pool.submit(_outside, args, victim, float(disruptor.eps))  # one core
        start = time.perf_counter()
        jobs = optimal_jobs(args.scenario, args.preset, agent, {args.zoo: victim}, search, out,
                            seeds=seeds)  # fmt: skip
        search_s = time.perf_counter() - start
        outer = outside.result()
    files = outer["files"]
    columns = {
        "nominal": AdversarySetup.nominal(),
        "outside SB3 adversary": AdversarySetup(
            {"preset": args.preset},
            {agent: SB3Checkpoint(files["path"], "ppo", files["normalizer"], deterministic=True)},
        ),
    }
    jobs += population_jobs(args.scenario, {args.zoo: victim}, columns, seeds=seeds)
    table = evaluate(jobs, workers=args.workers, progress=False)
    means = {c: float(np.mean(table.values(args.zoo, c))) for c in table.adversaries}
    nominal = means["nominal"]
    lines = [
        f"# The searched optimal attack beside an outside adversary: {args.zoo}",
        "",
        f"`python benchmarks/attack_strength.py --zoo {args.zoo} --br-steps {args.br_steps} "
        f"--grid {args.grid or 'all'} --select-seeds {args.select_seeds} --episodes "
        f"{args.episodes}`; {args.scenario}, threat model `{args.preset}` (eps {disruptor.eps}, "
        f"normalized units); calibration {before} before, {step_us(repeats=3):.1f} µs after. Mean true "
        f"return over {args.episodes} seeds, both sides deterministic.",
        "",
        "| column | return | of nominal |",
        "|---|---|---|",
        *[f"| {c} | {m:,.0f} | {100 * m / nominal:.0f} % |" for c, m in means.items()],
        "",
        f"The outside adversary in its own env (no advgame): {np.mean(outer['own_returns']):,.0f}"
        f". Wall time: the search {search_s / 60:.1f} min ({len(grid)} candidates on "
        f"{search.workers} worker(s)), the outside adversary {outer['train_s'] / 60:.1f} min on "
        "one core, beside each other.",
    ]
    (out / "strength.md").write_text("\n".join(lines) + "\n")
    print((out / "strength.md").read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--zoo", help="measure the searched optimal attack on this zoo agent")
    parser.add_argument("--grid", help="--zoo: OPTIMAL_GRID indices to search, e.g. 4,5 (all)")
    parser.add_argument("--select-seeds", type=int, default=10, help="--zoo: selection seeds")
    parser.add_argument("--scenario", default="Hopper-v5")
    parser.add_argument("--preset", default="atla", help="the one threat model of the table")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=20_480, help="protagonist steps per run")
    parser.add_argument("--br-steps", type=int, default=8_192, help="best-response steps")
    parser.add_argument("--episodes", type=int, default=3, help="episodes per seed and column")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="docs/attacks")
    args = parser.parse_args()
    if args.zoo:
        _strength(args)
        return
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(args.workers, mp_context=get_context("forkserver")) as pool:
        rows = list(pool.map(_seed_job, range(args.seeds), [args] * args.seeds))
    (out / "results.json").write_text(json.dumps({"args": vars(args), "per_seed": rows}, indent=2))
    (out / "attacks.md").write_text(_markdown(rows, args))
    print((out / "attacks.md").read_text())


if __name__ == "__main__":
    main()
