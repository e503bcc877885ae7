"""The demo: released agents under attack and noise; PPO and ATLA-PPO trained briefly, evaluated.

What the README's first command runs (``advgame demo``); `train_or_resume` is shared with the
reproduction scripts.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from advgame.core.config import read_json
from advgame.reports.report import DEFAULT_COST_LIMIT
from advgame.training import TrainConfig
from advgame.workflows.suite import evaluate_runs

__all__ = [
    "SAFE_COLUMNS",
    "ZOO_ATTACKS",
    "demo",
    "demo_safe",
    "demo_zoo",
    "safe_summary",
    "train_or_resume",
    "zoo_summary",
]

ZOO_ATTACKS = ("attack:random", "attack:mad", "attack:critic")
"""The demo's columns for the released agents, beside nominal and each agent's own released
adversary (``attack optimal``): every one is cheap to play (no critic to train)."""

SAFE_COLUMNS = ("preset:action-gauss-0.3",)
"""The demo's column for the released safe agents beside nominal: the paper's action noise."""

SAFE_SCENARIO = "SafetyHopper-v5"
"""The safe task whose released agents the demo plays."""

log = logging.getLogger(__name__)


def train_or_resume(cfg: TrainConfig, run_dir: Path) -> None:
    """Train `cfg` in `run_dir`, resume it if interrupted, or reuse it if it is complete."""
    from advgame.training import resume, train

    if (run_dir / "state.json").exists():
        state = read_json(run_dir / "state.json", "run state", ("iteration",))
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

    The columns are the default ones (nominal, the paper's random attacks, a scheduled shift,
    the learned adversary) and the white-box attacks, all in the ``atla`` threat model.

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
        train_or_resume(cfg, run_dir)
        runs.append(run_dir)
    return evaluate_runs(
        runs,
        out,
        seeds=2 if quick else 3,
        episodes=1,
        workers=workers,
        # today's columns and the worst-of-attacks suite (a small Robust Sarsa critic when quick)
        adversaries=("default", "attacks,samples=1000,epochs=2" if quick else "attacks"),
    )


def demo_zoo(
    out: Path, quick: bool = False, workers: int = 2, root: Path | None = None
) -> Path | None:
    """The released Hopper-v5 agents under the attack suite and their own adversaries.

    Every Hopper-v5 agent of the zoo (`advgame.workflows.zoo`, default the repository's ``zoo/``) is
    played nominally, under uniform noise, MAD and the critic attack, and against the learned
    adversary released with it, in the threat model it was released in; returns the folder's
    ``report.md``, or None when the zoo holds no Hopper agent (or one without an adversary).
    """
    from advgame.workflows import zoo

    found = [e for e in zoo.entries(root) if e.scenario == "Hopper-v5" and "adversary" in e.files]
    if not found:
        log.info("the zoo has no Hopper-v5 agent with an adversary; skipping its evaluation")
        return None
    released, own, threat = zoo.evaluation_inputs(
        [e.id for e in found], adversaries=True, root=root
    )
    return evaluate_runs(
        [],
        out,
        released=released,
        released_adversaries=own,
        threat=threat,
        adversaries=("attack:mad",) if quick else ZOO_ATTACKS,
        seeds=1 if quick else 5,
        episodes=1,
        workers=workers,
        budgets=(),
    )


def zoo_summary(folder: Path, root: Path | None = None) -> str:
    """The zoo table of `demo_zoo` in a few lines, and each agent's worst cell in the zoo.

    Per agent: its nominal return and the worst of the attacks the demo played (random, MAD,
    critic and its own released adversary: a few cheap ones, not the strongest), then the
    worst cell of its campaign's full table as the zoo's manifest records it (every attack,
    Robust Sarsa and the searched optimal attack included: `advgame.workflows.zoo.ZooEntry`).
    """
    from advgame.evaluation.table.payoff import PayoffTable
    from advgame.workflows import zoo

    table = PayoffTable.from_csv(folder / "payoff.csv")
    released = {e.id: e for e in zoo.entries(root)}
    lines = ["released Hopper-v5 agents (mean true return over the evaluation seeds):"]
    rows = table.metrics()
    wide = max((len(m["worst_adversary"]) for m in rows), default=0) + 2
    for m in rows:
        played = f"worst of these {m['adversaries']} attacks"
        line = (
            f"  {m['protagonist']:<19} nominal {m['nominal']:5.0f}   {played} "
            f"{m['worst']:5.0f} {'(' + m['worst_adversary'] + ')':<{wide}}"
        )
        entry = released.get(m["protagonist"])
        if entry is not None:
            line += (
                f"   zoo's full table: worst {entry.worst_attack_return:5.0f} "
                f"({entry.worst_attack})"
            )
        lines.append(line.rstrip())
    return "\n".join(lines)


def demo_safe(
    out: Path, quick: bool = False, workers: int = 2, root: Path | None = None
) -> Path | None:
    """The released SafetyHopper-v5 agents nominally and under the paper's action noise.

    Every SafetyHopper-v5 agent of the zoo (plain PPO and the constrained learners) plays
    `SAFE_COLUMNS` beside nominal; the report shows return and true episode cost against the
    limit. Returns the folder's ``report.md``, or None when the zoo holds no such agent.
    """
    from advgame.workflows import zoo

    found = [e.id for e in zoo.entries(root) if e.scenario == SAFE_SCENARIO]
    if not found:
        log.info("the zoo has no %s agent; skipping the safe evaluation", SAFE_SCENARIO)
        return None
    released, _, _ = zoo.evaluation_inputs(found, root=root)
    return evaluate_runs(
        [],
        out,
        released=released,
        adversaries=SAFE_COLUMNS,
        seeds=1 if quick else 3,
        episodes=1,
        workers=workers,
        budgets=(),
    )


def safe_summary(folder: Path, limit: float = DEFAULT_COST_LIMIT) -> str:
    """The table of `demo_safe` in a few lines: return, episode cost and how often within `limit`."""
    from advgame.evaluation.table.payoff import PayoffTable

    table = PayoffTable.from_csv(folder / "payoff.csv")
    cells = {(c["protagonist"], c["adversary"]): c for c in table.safety(limit)}
    lines = [f"released {SAFE_SCENARIO} agents (mean true return / episode cost, limit {limit:g}):"]
    for p in table.protagonists:
        parts = []
        for a in table.adversaries:
            c = cells.get((p, a))
            if c is not None:
                within = f"{100 * c['satisfied']:3.0f} % within"
                parts.append(f"{a} {c['return']:6.0f} / {c['cost']:4.0f} ({within})")
        lines.append(f"  {p:<22} " + "   ".join(parts))
    return "\n".join(lines)
