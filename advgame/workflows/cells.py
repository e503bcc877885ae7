"""The cells of a suite's table: its columns and jobs, before anything is played.

`table_jobs` is what `advgame.workflows.suite.evaluate_policies` plays (but for the ``attack
optimal`` column, which its search decides) and `search_jobs` the candidates its search
trains, so a campaign's ``--status`` can count the cells and candidates already kept in part
files without playing or learning anything.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from advgame.evaluation import NOMINAL, AdversarySetup, EvalJob, population_jobs
from advgame.evaluation.attacks.optimal import OptimalSearch, candidate_jobs
from advgame.evaluation.table.columns import adversary_columns
from advgame.evaluation.table.threat import default_threat, observation_agent

__all__ = ["SCHEDULE_EPISODES", "search_jobs", "table_jobs"]

SCHEDULE_EPISODES = 8
"""Episodes per seed in the scheduled column: seed ``s`` plays episodes ``8s + 1`` to ``8s + 8``
of a per-episode schedule (`advgame.evaluation.table.jobs.schedule_index`)."""


def table_jobs(
    scenario: str,
    protagonists: Mapping[str, Any],
    adversaries: Sequence[str] | Mapping[str, AdversarySetup],
    *,
    runs: Mapping[str, Path],
    last: int | None = None,
    sample: int | None = None,
    seed: int = 0,
    seeds: int = 3,
    episodes: int = 1,
    threat: str | None = None,
) -> tuple[dict[str, AdversarySetup], list[EvalJob]]:
    """A suite table's columns and jobs, without the ``attack optimal`` column.

    What `advgame.workflows.suite.evaluate_policies` plays, from the same arguments; nothing is
    played or learned here.
    """
    if isinstance(adversaries, Mapping):
        columns = {NOMINAL: AdversarySetup.nominal(), **adversaries}
    else:
        columns = adversary_columns(scenario, adversaries, runs=runs, last=last, sample=sample,
                                    seed=seed, protagonists=protagonists, threat=threat)  # fmt: skip
    jobs = population_jobs(scenario, protagonists, columns, seeds=tuple(range(seeds)),
                           episodes=episodes)  # fmt: skip
    # A per-episode schedule plays episode s·E + e + 1 in episode e of seed s: more episodes
    # per seed cover more of its sequence.
    jobs = [
        replace(j, episodes=max(episodes, SCHEDULE_EPISODES))
        if j.adversary.startswith("scheduled")
        else j
        for j in jobs
    ]
    return columns, jobs


def search_jobs(
    scenario: str,
    protagonists: Mapping[str, Any],
    search: OptimalSearch,
    threat: str | None = None,
) -> list[Any]:
    """The candidates (`BestResponseJob`) the ``attack optimal`` search trains, in its order.

    What `advgame.workflows.suite.evaluate_policies` trains for `protagonists` with `search`
    in `threat` (default `advgame.evaluation.table.columns.default_threat`); nothing is trained
    here.
    """
    threat = threat or default_threat(scenario)
    agent = observation_agent(scenario, threat)
    return [job for _, _, job in candidate_jobs(scenario, threat, agent, protagonists, search)]
