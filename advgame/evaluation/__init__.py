"""Evaluation, the library: playing robustness tables and learning the attacks they need.

* `advgame.evaluation.table`: playing a table. Who plays (`protagonists`), against whom
  (`columns`), the jobs of a table's cells (`jobs`), which cells can be played (`applicable`),
  running them (`running`, `batched`), the resulting `PayoffTable` and its robust metrics
  (`payoff`), and learned adversaries read back from runs (`snapshots`).
* `advgame.evaluation.attacks`: attacks learned ahead of a table: the searched optimal attack
  (`optimal`) and exploitability by a best response (`exploit`).

Jobs run on `advgame.runner` (a process pool or Ray); results are written by `advgame.reports`;
the ready-made workflows that do all of it (`evaluate_policies`, campaigns, the zoo) live in
`advgame.workflows`. One `EvalJob` is one cell of the payoff matrix: a protagonist against one
adversary set-up over some seeds; every episode becomes one row of a `PayoffTable`, which saves
to CSV/JSON and computes the design's robust metrics on the *true* return::

    setups = {"nominal": AdversarySetup.nominal(),
              "gauss": AdversarySetup.from_preset("Hopper-v5", "state-gauss-0.1")}
    jobs = population_jobs("Hopper-v5", {"mine": my_policy}, setups, seeds=(0, 1))
    evaluate(jobs, workers=2).metrics(alpha=0.1)

This module only re-exports the table's public names, so ``from advgame.evaluation import ...``
reaches them.
"""

from __future__ import annotations

from advgame.evaluation.table.applicable import not_applicable
from advgame.evaluation.table.columns import COLUMN_KINDS, adversary_columns, describe_column
from advgame.evaluation.table.jobs import (
    SEED_STRIDE,
    AdversarySetup,
    EvalJob,
    budget_sweep,
    lockstep_groups,
    population_jobs,
    schedule_index,
    shift_grid,
    split_seeds,
    unit_size,
)
from advgame.evaluation.table.payoff import (
    COLUMNS,
    NOMINAL,
    PayoffTable,
    ci95,
    cvar,
    degradation,
    worst_case,
)
from advgame.evaluation.table.protagonists import (
    check_protagonists,
    run_protagonist,
    sb3_protagonist,
    team_protagonist,
)
from advgame.evaluation.table.running import evaluate, run_job, use_executor
from advgame.runner.run import EXECUTORS

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
    "lockstep_groups",
    "not_applicable",
    "population_jobs",
    "run_job",
    "run_protagonist",
    "sb3_protagonist",
    "schedule_index",
    "shift_grid",
    "split_seeds",
    "team_protagonist",
    "unit_size",
    "use_executor",
    "worst_case",
]
