"""Robust evaluation: payoff tables of protagonists × adversaries × seeds, and robust metrics.

One `EvalJob` is one cell of the payoff matrix: a protagonist against one adversary set-up over
some seeds. Jobs are pure, picklable values, so `evaluate` runs them (one unit per seed) in
this process, in a process pool or as Ray tasks (`advgame.evaluation.executor`). Every episode becomes
one row of a `PayoffTable`, which saves to CSV/JSON and computes the design's robust metrics on
the *true* return: nominal, mean, worst case, CVaR and the degradation from nominal::

    setups = {"nominal": AdversarySetup.nominal(),
              "gauss": AdversarySetup.from_preset("Hopper-v5", "state-gauss-0.1")}
    jobs = population_jobs("Hopper-v5", {"mine": my_policy}, setups, seeds=(0, 1))
    evaluate(jobs, workers=2).metrics(alpha=0.1)

Who is evaluated and against whom, for fixed policies from anywhere: `sb3_protagonist` (an SB3
model trained elsewhere, behind its `VecNormalize` statistics), `team_protagonist`,
`run_protagonist`, `check_protagonists`; `adversary_columns` turns column specs
(``preset:NAME``, ``population:RUN_DIR``, ...) into `AdversarySetup`s; `evaluate_policies` does
all of it and writes a self-contained results folder with its report::

    mine = sb3_protagonist("model.zip", normalizer="vecnormalize.pkl")
    cols = adversary_columns("Hopper-v5", ["preset:state-gauss-0.1", "population:runs/atla"])
    evaluate_policies("Hopper-v5", {"mine": mine}, "results", adversaries=cols)

Jobs and their builders live in `advgame.evaluation.jobs`, tables and metrics in
`advgame.evaluation.payoff`, protagonists in `advgame.evaluation.protagonists`, columns in
`advgame.evaluation.columns`, `evaluate` and `run_job` in `advgame.evaluation.running`, the
check of which cells a column can play in `advgame.evaluation.applicable`; this module
re-exports them, so ``from advgame.evaluation import ...`` reaches all of them.
"""

from __future__ import annotations

from typing import Any

from advgame.evaluation.applicable import not_applicable
from advgame.evaluation.columns import COLUMN_KINDS, adversary_columns, describe_column
from advgame.evaluation.executor import EXECUTORS
from advgame.evaluation.jobs import (
    SEED_STRIDE,
    AdversarySetup,
    EvalJob,
    budget_sweep,
    lockstep_groups,
    population_jobs,
    shift_grid,
    split_seeds,
    unit_size,
)
from advgame.evaluation.payoff import (
    COLUMNS,
    NOMINAL,
    PayoffTable,
    ci95,
    cvar,
    degradation,
    worst_case,
)
from advgame.evaluation.protagonists import (
    check_protagonists,
    run_protagonist,
    sb3_protagonist,
    team_protagonist,
)
from advgame.evaluation.running import evaluate, run_job, use_executor

__all__ = [
    "COLUMNS",
    "COLUMN_KINDS",
    "EXECUTORS",
    "NOMINAL",
    "SEED_STRIDE",
    "AdversarySetup",
    "EvalJob",
    "PayoffTable",
    "adversary_columns",
    "budget_sweep",
    "check_protagonists",
    "ci95",
    "cvar",
    "degradation",
    "describe_column",
    "evaluate",
    "evaluate_policies",
    "lockstep_groups",
    "not_applicable",
    "population_jobs",
    "run_job",
    "run_protagonist",
    "sb3_protagonist",
    "shift_grid",
    "split_seeds",
    "team_protagonist",
    "unit_size",
    "use_executor",
    "worst_case",
]


def __getattr__(name: str) -> Any:
    """`evaluate_policies` lives in `advgame.evaluation.suite` (it writes reports), loaded on first use."""
    if name == "evaluate_policies":
        from advgame.evaluation.suite import evaluate_policies

        return evaluate_policies
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
