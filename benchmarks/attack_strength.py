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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="Hopper-v5")
    parser.add_argument("--preset", default="atla", help="the one threat model of the table")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=20_480, help="protagonist steps per run")
    parser.add_argument("--br-steps", type=int, default=8_192, help="best-response steps")
    parser.add_argument("--episodes", type=int, default=3, help="episodes per seed and column")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="docs/attacks")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(args.workers, mp_context=get_context("forkserver")) as pool:
        rows = list(pool.map(_seed_job, range(args.seeds), [args] * args.seeds))
    (out / "results.json").write_text(json.dumps({"args": vars(args), "per_seed": rows}, indent=2))
    (out / "attacks.md").write_text(_markdown(rows, args))
    print((out / "attacks.md").read_text())


if __name__ == "__main__":
    main()
