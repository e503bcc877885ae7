"""The demo: the zoo's Hopper agents under attack; PPO and ATLA-PPO trained briefly, evaluated.

What the README's first command runs (``advgame demo``); `train_or_resume` is shared with the
reproduction scripts.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from advgame.core.config import read_json
from advgame.evaluation.suite import evaluate_runs
from advgame.training import TrainConfig

__all__ = ["ZOO_ATTACKS", "demo", "demo_zoo", "train_or_resume", "zoo_summary"]

ZOO_ATTACKS = ("attack:random", "attack:mad", "attack:critic")
"""The demo's columns for the released agents, beside nominal and each agent's own released
adversary (``attack optimal``): every one is cheap to play (no critic to train)."""

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

    Every Hopper-v5 agent of the zoo (`advgame.zoo`, default the repository's ``zoo/``) is
    played nominally, under uniform noise, MAD and the critic attack, and against the learned
    adversary released with it, in the threat model it was released in; returns the folder's
    ``report.md``, or None when the zoo holds no Hopper agent (or one without an adversary).
    """
    from advgame import zoo

    found = [e for e in zoo.entries(root) if e.scenario == "Hopper-v5" and "adversary" in e.files]
    if not found:
        log.info("the zoo has no Hopper-v5 agent with an adversary; skipping its evaluation")
        return None
    return evaluate_runs(
        [],
        out,
        zoo=[e.id for e in found],
        zoo_root=root,
        zoo_adversaries=True,
        adversaries=("attack:mad",) if quick else ZOO_ATTACKS,
        seeds=1 if quick else 5,
        episodes=1,
        workers=workers,
        budgets=(),
    )


def zoo_summary(folder: Path) -> str:
    """The zoo table of `demo_zoo` in a few lines: each agent's nominal and worst-attack return."""
    from advgame.evaluation.payoff import PayoffTable

    table = PayoffTable.from_csv(folder / "payoff.csv")
    lines = ["released Hopper-v5 agents (mean true return over the evaluation seeds):"]
    for m in table.metrics():
        lines.append(
            f"  {m['protagonist']:<18} nominal {m['nominal']:7.0f}   under the strongest attack "
            f"{m['worst']:7.0f}  ({m['worst_adversary']})"
        )
    return "\n".join(lines)
