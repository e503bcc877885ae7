"""A small reproduction of the paper's robustness findings, with intervals over seeds.

Claims checked (default Hopper-v5; PPO, the paper's hyper-parameters except the step budget):

1. PPO's return falls as Gaussian state noise rises σ = 0 → 0.1 → 0.15, and more in the
   post-training setting (trained nominally, noise only at test) than in-training (trained and
   tested with the noise) — the paper's Fig. 3.
2. A learned observation adversary (a PPO best response trained against the frozen policy,
   ATLA's L∞ budget ε = 0.075 in normalized units) hurts PPO more than random noise filling
   the same budget (`RandomAdversary`).
3. ATLA-PPO beats PPO under that learned attack (each attacked by its own best response).

Per seed: PPO nominal, PPO trained with σ = 0.1 and with σ = 0.15, ATLA-PPO (same protagonist
steps plus as many adversary steps); then best responses and evaluation. Seeds run in parallel
worker processes. Results: ``<out>/results.json``, ``<out>/reproduction.md`` (mean ± 95 %
Student-t interval over seed means) and the runs themselves.

Run: ``python benchmarks/reproduce_robustness.py --seeds 3 --steps 40000 --out docs/reproduction``
(about 40 minutes on 2 cores with the defaults).
"""

from __future__ import annotations

import argparse
import json
import logging
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
from _common import fmt as fmt_values

SIGMAS = (0.0, 0.1, 0.15)


def _train_seed(seed: int, steps: int, out: str, scenario: str, attack: str) -> dict[str, str]:
    import torch

    from advgame.training import METHODS, TrainConfig
    from advgame.workflows.suite import _train_or_resume

    torch.set_num_threads(1)
    iters = max(steps // 2048, 1)
    common = {
        "scenario": scenario,
        "seed": seed,
        "iterations": iters,
        "protagonist_steps": 2048,
        "adversary_steps": 2048,
        "eval_episodes": 1,
    }
    runs = {
        "ppo": {**common, **METHODS["ppo"]},
        "ppo-noise-0.1": {**common, "preset": "state-gauss-0.1", "learned": []},
        "ppo-noise-0.15": {**common, "preset": "state-gauss-0.15", "learned": []},
        "atla": {**common, **METHODS["atla"], "preset": attack},
    }
    dirs = {}
    for name, fields in runs.items():
        run_dir = Path(out) / "runs" / f"{name}-s{seed}"
        _train_or_resume(TrainConfig(**fields), run_dir)
        dirs[name] = str(run_dir)
    return dirs


def _mean_return(
    scenario: str, kwargs: dict, protagonist: Any, adversaries: dict, seed: int, episodes: int
) -> float:
    import advgame
    from advgame.core.episodes import rollout

    game = advgame.make(scenario, phase="eval", **kwargs)
    results = rollout(
        game,
        {"protagonist": protagonist, **adversaries},
        seed=10_000 + seed * 100,
        episodes=episodes,
    )
    game.close()
    return float(np.mean([r.true_return for r in results]))


def _evaluate_seed(
    seed: int, dirs: dict[str, str], br_steps: int, episodes: int, out: str, sc: str, attack: str
) -> dict:
    import torch

    from advgame.adversaries import GaussianAdversary, RandomAdversary
    from advgame.evaluation.attacks.exploit import best_responses
    from advgame.workflows.suite import run_protagonist

    torch.set_num_threads(1)
    prot = {name: run_protagonist(Path(d))[1] for name, d in dirs.items()}
    noise = {
        s: (
            {"disruptors": {"observation": {"bounded": False}}},
            {"observation_adversary": GaussianAdversary(std=s)} if s else {},
        )
        for s in SIGMAS
    }
    row: dict[str, float] = {}
    for s in SIGMAS:  # post-training: trained nominally, tested with noise
        row[f"post σ={s}"] = _mean_return(sc, noise[s][0], prot["ppo"], noise[s][1], seed, episodes)
    row["in σ=0"] = row["post σ=0.0"]
    for s in SIGMAS[1:]:  # in-training: trained and tested with the same noise
        row[f"in σ={s}"] = _mean_return(
            sc, noise[s][0], prot[f"ppo-noise-{s}"], noise[s][1], seed, episodes
        )
    atla = {"preset": attack}
    for name in ("ppo", "atla"):
        row[f"{name} nominal"] = _mean_return(
            sc, {"preset": "default"}, prot[name], {}, seed, episodes
        )
        row[f"{name} random ε"] = _mean_return(
            sc, atla, prot[name], {"observation_adversary": RandomAdversary()}, seed, episodes
        )
        br = best_responses(
            sc,
            attack,
            prot[name],
            Path(out) / "br" / f"{name}-s{seed}",
            steps=br_steps,
            seed=seed,
        )
        row[f"{name} learned ε"] = _mean_return(sc, atla, prot[name], br, seed, episodes)
    return row


def _seed_job(seed: int, args: argparse.Namespace) -> dict:
    logging.basicConfig(level=logging.WARNING)
    out = str(args.out)
    dirs = _train_seed(seed, args.steps, out, args.scenario, args.attack_preset)
    return _evaluate_seed(
        seed, dirs, args.br_steps, args.episodes, out, args.scenario, args.attack_preset
    )


def _markdown(rows: list[dict], args: argparse.Namespace) -> str:
    fmt = lambda k: fmt_values([r[k] for r in rows])  # noqa: E731
    lines = [
        f"# Reproduction: robustness of PPO and ATLA-PPO on {args.scenario}",
        "",
        f"Measured with `python benchmarks/reproduce_robustness.py --scenario {args.scenario} "
        f"--attack-preset {args.attack_preset} --seeds {args.seeds} --steps "
        f"{args.steps} --br-steps {args.br_steps} --episodes {args.episodes}`: {args.seeds} seeds, "
        f"{args.steps} protagonist steps per run (ATLA: as many adversary steps again), "
        f"best responses trained {args.br_steps} steps, {args.episodes} evaluation episodes per "
        "seed. Mean true return ± half-width of a 95 % Student-t interval over seed means.",
        "",
        "## 1. Gaussian state noise, in-training vs post-training (paper Fig. 3)",
        "",
        "| σ | post-training (trained nominal) | in-training (trained with σ) |",
        "|---|---|---|",
    ]
    lines += [
        f"| {s} | {fmt(f'post σ={s}')} | {fmt(f'in σ={s}' if s else 'in σ=0')} |" for s in SIGMAS
    ]
    lines += [
        "",
        f"## 2-3. Learned vs random attack in the same budget (preset `{args.attack_preset}`)",
        "",
        "| protagonist | nominal | random noise in ε | learned adversary in ε |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {n} | {fmt(f'{n} nominal')} | {fmt(f'{n} random ε')} | {fmt(f'{n} learned ε')} |"
        for n in ("ppo", "atla")
    ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="Hopper-v5")
    parser.add_argument("--attack-preset", default="atla", help="normalized L∞ observation preset")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=40_000, help="protagonist steps per run")
    parser.add_argument("--br-steps", type=int, default=15_000, help="best-response steps")
    parser.add_argument("--episodes", type=int, default=5, help="evaluation episodes per seed")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="docs/reproduction")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ctx = get_context("forkserver")
    with ProcessPoolExecutor(args.workers, mp_context=ctx) as pool:
        futures = [pool.submit(_seed_job, s, args) for s in range(args.seeds)]
        rows = [f.result() for f in futures]
    (out / "results.json").write_text(json.dumps({"args": vars(args), "per_seed": rows}, indent=2))
    (out / "reproduction.md").write_text(_markdown(rows, args))
    print((out / "reproduction.md").read_text())


if __name__ == "__main__":
    main()
