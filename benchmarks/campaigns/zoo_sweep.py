"""Return vs attack budget for the zoo's released agents: ε from 0 to 2x the threat model's.

For every released agent of one scenario (default Hopper-v5), uniform noise and MAD play an
L∞ observation disruptor of ε = f x the ATLA budget, f in 0, 0.25, ..., 2, in the agent's own
normalized units (ATLA's convention, as the ``atla`` preset), for ``--seeds`` episodes each.
Writes ``sweep.csv`` (one row per episode, ``budget`` = ε) and ``sweep-<attack>.png`` (return
vs ε, one line per agent, 95 % bands over seeds) into ``--out`` (default the campaign's folder).

    python benchmarks/campaigns/zoo_sweep.py --out zoo/hopper --seeds 5 --workers 2

Measured numbers go to docs/zoo.md; run it on quiet cores.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

FACTORS = (0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0)
"""Multiples of the threat model's ε swept."""


def sweep_jobs(scenario: str, eps: float, released: dict, seeds: int) -> list:
    """Uniform noise and MAD at each ε = factor x `eps`, every released agent, `seeds` seeds."""
    from advgame.adversaries import MADAttack, RandomAdversary
    from advgame.evaluation import EvalJob

    jobs = []
    for factor in FACTORS:
        e = round(factor * eps, 6)
        game = {"disruptors": {"observation": {"eps": e, "space": "normalized"}}}
        for attack, spec in (("random", RandomAdversary()), ("mad", MADAttack())):
            for name, protagonist in released.items():
                jobs.append(
                    EvalJob(
                        scenario=scenario,
                        make_kwargs=game,
                        protagonist=name,
                        protagonist_spec=protagonist,
                        adversary=f"{attack} eps={e:g}",
                        adversary_specs={"observation_adversary": spec},
                        seeds=tuple(range(seeds)),
                        tags={"budget": e, "attack": attack},
                    )
                )
    return jobs


def main() -> None:
    """Run the sweep over the zoo's agents of ``--scenario``; write the CSV and the plots."""
    from advgame.evaluation import evaluate
    from advgame.reports.plots import plot_budget_curve
    from advgame.scenarios.mujoco import ATLA_EPS
    from advgame.workflows import zoo

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default="Hopper-v5")
    p.add_argument("--out", type=Path, default=Path("zoo/hopper"))
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--root", type=Path, help="the zoo (default: the repository's zoo/)")
    args = p.parse_args()
    found = [e for e in zoo.entries(args.root) if e.scenario == args.scenario]
    if not found:
        raise SystemExit(f"No {args.scenario} agent in the zoo; release a campaign first.")
    released = {e.id.split("/", 1)[1]: zoo.load(e.id, args.root) for e in found}
    eps = ATLA_EPS[args.scenario]
    start = time.perf_counter()
    table = evaluate(
        sweep_jobs(args.scenario, eps, released, args.seeds), workers=args.workers, progress=True
    )
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "sweep.csv")
    for attack in ("random", "mad"):
        rows = [r for r in table.rows if r["attack"] == attack]
        plot_budget_curve(
            rows,
            args.out / f"sweep-{attack}.png",
            title=f"{args.scenario}: return vs ε ({attack}; normalized units, ATLA ε = {eps})",
        )
    print(f"{len(table)} episodes in {time.perf_counter() - start:.0f} s -> {args.out}/sweep.csv")


if __name__ == "__main__":
    main()
