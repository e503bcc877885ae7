"""Which of the outside recipe's differences made the first optimal-attack search weak (issue 36).

The first search's candidate 0 (`OPTIMAL_GRID[0]`) and the outside SB3 recipe (`SB3_RECIPE`)
differ in three settings: the learning rate (annealed to 0 over the run vs constant), the
envs per update (1 x 2048 steps vs 4 x 512) and the value-loss weight (0.25 vs 0.5). This trains,
against the released zoo agent ``--zoo``, the recipe, the recipe with each one of the three
reverted, and candidate 0 (all three reverted), each ``--repeats`` times with its own training
seed, ``--br-steps`` steps each, through advgame's own search (`optimal_jobs`: the candidates
are its jobs, resumable from their part files under ``--out``). Every candidate is played
deterministically on the search's ``--select-seeds`` selection seeds, beside the agent's
nominal return on the same seeds. Written: ``<out>/factors.md`` (per variant each repeat's
return, their mean and its share of nominal) and the search's ``<out>/optimal.json``.
Run: ``python benchmarks/attack_factors.py --zoo hopper/ppo --repeats 3 --out
docs/attacks/factors-hopper``. The grid is repeat-major, so a later run with more
``--repeats`` reuses the candidates already trained.
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
from pathlib import Path
from typing import Any

import numpy as np


def variants() -> dict[str, dict[str, Any]]:
    """The recipe, the recipe with one setting of candidate 0 each, and candidate 0."""
    from advgame.evaluation.attacks.optimal import OPTIMAL_GRID, SB3_RECIPE

    return {
        "SB3 recipe": dict(SB3_RECIPE),
        "recipe, lr annealed to 0": {**SB3_RECIPE, "lr_decay": True},
        "recipe, 1 env x 2048 steps": {**SB3_RECIPE, "n_envs": 1, "n_steps": 2048},
        "recipe, value weight 0.25": {**SB3_RECIPE, "vf_coef": 0.25},
        "first search's candidate 0 (all three)": dict(OPTIMAL_GRID[0]),
    }


def main() -> None:
    """Train the variants, play them on the selection seeds, write the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--zoo", default="hopper/ppo", help="the released agent attacked")
    parser.add_argument("--repeats", type=int, default=3, help="training seeds per variant")
    parser.add_argument("--br-steps", type=int, default=200_000, help="steps per candidate")
    parser.add_argument("--select-seeds", type=int, default=10)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", default="docs/attacks/factors-hopper")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    from calibrate import step_us

    from advgame.evaluation import AdversarySetup, evaluate, population_jobs
    from advgame.evaluation.attacks.optimal import OptimalSearch, optimal_jobs
    from advgame.evaluation.table.threat import observation_agent
    from advgame.workflows import zoo

    entry, victim = zoo.entry(args.zoo), zoo.load(args.zoo)
    agent = observation_agent(entry.scenario, entry.threat)
    named = variants()
    grid = tuple(v for _ in range(args.repeats) for v in named.values())  # repeat-major
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    before = step_us(repeats=3)
    search = OptimalSearch(
        steps=args.br_steps, grid=grid, select_seeds=args.select_seeds, workers=args.workers
    )
    optimal_jobs(entry.scenario, entry.threat, agent, {args.zoo: victim}, search, out, seeds=[0])
    found = json.loads((out / "optimal.json").read_text())[args.zoo]["candidates"]
    select = list(range(10_000, 10_000 + args.select_seeds))  # the search's selection seeds
    nominal_jobs = population_jobs(
        entry.scenario, {args.zoo: victim}, {"nominal": AdversarySetup.nominal()}, seeds=select
    )
    nominal = float(np.mean(evaluate(nominal_jobs, progress=False).values(args.zoo, "nominal")))
    after = step_us(repeats=3)
    lines = [
        f"# What made the first search weak: one factor at a time on {args.zoo}",
        "",
        f"`python benchmarks/attack_factors.py --zoo {args.zoo} --repeats {args.repeats} "
        f"--br-steps {args.br_steps} --select-seeds {args.select_seeds}`; {entry.scenario}, "
        f"threat model `{entry.threat}`; calibration {before:.1f} µs per raw HalfCheetah-v5 "
        f"step before, {after:.1f} after. Each candidate trained {args.br_steps:,} steps with "
        f"its own seed, then played deterministically on the {args.select_seeds} selection "
        f"seeds; nominal on the same seeds: {nominal:,.0f}.",
        "",
        "| variant | return per training seed | mean | of nominal |",
        "|---|---|---|---|",
    ]
    for i, name in enumerate(named):
        returns = [found[r * len(named) + i]["selection_return"] for r in range(args.repeats)]
        mean = statistics.fmean(returns)
        each = ", ".join(f"{x:,.0f}" for x in returns)
        lines.append(f"| {name} | {each} | {mean:,.0f} | {100 * mean / nominal:.0f} % |")
    (out / "factors.md").write_text("\n".join(lines) + "\n")
    print((out / "factors.md").read_text())


if __name__ == "__main__":
    main()
