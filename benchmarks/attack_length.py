"""How the optimal attack's strength grows with its training length: one long run, snapshots (issue 36).

One learned observation adversary with the outside SB3 recipe (`SB3_RECIPE`, the search's
strongest entry) trains against the released zoo agent ``--zoo`` for ``--steps`` steps, as the
search's candidates train (`advgame.training.best_response.best_response_side`: the same views,
budgets and normalizer), saved every ``--every`` steps under ``<out>/snapshots/STEPS/``. A
rerun continues from the last saved snapshot, so a run cut short by the end of a session loses
at most one stretch. Each snapshot is then played deterministically on the search's
``--select-seeds`` selection seeds beside the agent's nominal return on the same seeds; written
to ``<out>/length.md`` with the calibration (a raw HalfCheetah-v5 step) before and after.
One run is one training seed: the search's candidates of one recipe vary as much by seed
(docs/attacks.md), so read the curve's trend, not a single point.
Run: ``python benchmarks/attack_length.py --zoo walker2d/ppo --steps 3000000 --every 500000
--out docs/attacks/length-walker2d``.
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np

DONE = "done"
"""The marker a snapshot folder gets once its files are all written."""


def main() -> None:
    """Train (or continue) the long run, play every snapshot, write the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--zoo", default="walker2d/ppo", help="the released agent attacked")
    parser.add_argument("--steps", type=int, default=3_000_000)
    parser.add_argument("--every", type=int, default=500_000, help="steps between snapshots")
    parser.add_argument("--seed", type=int, default=0, help="the adversary's training seed")
    parser.add_argument("--select-seeds", type=int, default=10)
    parser.add_argument("--out", default="docs/attacks/length-walker2d")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    from calibrate import step_us

    from advgame.agents.common.checkpoint import SB3Checkpoint
    from advgame.evaluation import AdversarySetup, evaluate, population_jobs
    from advgame.evaluation.attacks.optimal import SB3_RECIPE
    from advgame.evaluation.table.threat import observation_agent
    from advgame.training.best_response import BestResponseJob, MixtureSpec, best_response_side
    from advgame.workflows import zoo

    entry, victim = zoo.entry(args.zoo), zoo.load(args.zoo)
    agent = observation_agent(entry.scenario, entry.threat)
    job = BestResponseJob(
        name=f"{args.zoo}/length", scenario=entry.scenario,
        make_kwargs={"preset": entry.threat}, agent=agent, hparams=dict(SB3_RECIPE),
        opponents={"protagonist": MixtureSpec((victim,), (1.0,))}, steps=args.steps,
        seed=args.seed,
    )  # fmt: skip
    out = Path(args.out)
    marks = list(range(args.every, args.steps + 1, args.every))
    folders = {m: out / "snapshots" / str(m) for m in marks}
    before = step_us(repeats=3)
    done = [m for m in marks if (folders[m] / DONE).exists()]
    last = folders[done[-1]] if done else None
    if len(done) < len(marks):
        side, rescale, _ = best_response_side(job, last)
        try:
            for m in marks[len(done) :]:
                start = time.perf_counter()
                rescale()
                side.learn(m - side.steps)
                side.save(folders[m])
                (folders[m] / DONE).write_text(f"{side.steps} steps\n")
                logging.info("snapshot %d: %.0f s", m, time.perf_counter() - start)
        finally:
            side.close()
    seeds = list(range(10_000, 10_000 + args.select_seeds))  # the search's selection seeds
    columns = {"nominal": AdversarySetup.nominal()}
    for m in marks:
        spec = SB3Checkpoint(
            str(folders[m] / f"{agent}.zip"), "ppo",
            str(folders[m] / f"{agent}_obs_norm.npz"), deterministic=True,
        )  # fmt: skip
        columns[f"{m:,} steps"] = AdversarySetup({"preset": entry.threat}, {agent: spec})
    table = evaluate(population_jobs(entry.scenario, {args.zoo: victim}, columns, seeds=seeds))
    means = {c: float(np.mean(table.values(args.zoo, c))) for c in columns}
    nominal = means["nominal"]
    lines = [
        f"# The optimal attack's strength against its training length: {args.zoo}",
        "",
        f"`python benchmarks/attack_length.py --zoo {args.zoo} --steps {args.steps} --every "
        f"{args.every} --seed {args.seed} --select-seeds {args.select_seeds}`; {entry.scenario}, "
        f"threat model `{entry.threat}`; the outside SB3 recipe, one training seed, snapshots "
        f"played deterministically on the {args.select_seeds} selection seeds. Calibration "
        f"{before:.1f} µs per raw HalfCheetah-v5 step before, {step_us(repeats=3):.1f} after.",
        "",
        "| adversary | return | of nominal |",
        "|---|---|---|",
        *[f"| {c} | {m:,.0f} | {100 * m / nominal:.0f} % |" for c, m in means.items()],
    ]
    (out / "length.md").write_text("\n".join(lines) + "\n")
    print((out / "length.md").read_text())


if __name__ == "__main__":
    main()
