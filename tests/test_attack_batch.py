"""White-box attacks batched across lockstep games: one walk over [N, k] for all the games of
a group gives every game the rows it gets alone (same seeds, same episodes, same clips)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from advgame.adversaries import CriticAttack, MADAttack, RobustSarsaAttack
from advgame.adversaries.whitebox_walk import WhiteBoxAttackPolicy
from advgame.evaluation import (
    AdversarySetup,
    evaluate,
    population_jobs,
    run_job,
    sb3_protagonist,
    split_seeds,
)

OBS = "observation_adversary"


def _setups(tmp_path: Path) -> dict[str, AdversarySetup]:
    l2 = {"disruptors": {"observation": {"eps": 0.2, "norm": "l2"}}}
    rs = RobustSarsaAttack(samples=500, epochs=2, cache_dir=str(tmp_path))
    return {
        "mad": AdversarySetup({"preset": "default"}, {OBS: MADAttack(steps=4)}),
        "critic": AdversarySetup({"preset": "default"}, {OBS: CriticAttack(steps=3, restarts=1)}),
        "mad l2": AdversarySetup(l2, {OBS: MADAttack(steps=3, restarts=1)}),
        "rs": AdversarySetup({"preset": "default"}, {OBS: rs}),
    }


def _rows(rows: list[dict[str, Any]]) -> list[tuple]:
    keys = ("adversary", "seed", "episode", "true_return", "length", "clipped", "terminated")
    return sorted(tuple(r[k] for k in keys) for r in rows)


def _walk_sizes(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """From now on, the number of games each attack walk serves, in order."""
    sizes: list[int] = []
    group = WhiteBoxAttackPolicy.act_group

    def spy(policies: Any, observations: Any) -> Any:
        sizes.append(len(policies))
        return group(policies, observations)

    monkeypatch.setattr(WhiteBoxAttackPolicy, "act_group", staticmethod(spy))
    return sizes


def test_batched_attacks_give_every_game_its_own_rows(
    pendulum_ppo: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    prots = {"ppo": sb3_protagonist(pendulum_ppo, raw_observations=True)}
    jobs = population_jobs("InvertedPendulum-v5", prots, _setups(tmp_path), seeds=(0, 1, 2, 3))
    sizes = _walk_sizes(monkeypatch)
    batched = evaluate(jobs, progress=False)  # one process: jobs in lockstep groups
    assert max(sizes) >= 4  # the games of a group were attacked in one walk
    sizes.clear()
    alone = [row for unit in split_seeds(jobs, 1) for row in run_job(unit)]
    assert max(sizes) == 1  # one game at a time
    assert _rows(batched.rows) == _rows(alone)
    assert all(r["clipped"] == 0 for r in batched.rows)  # in the budget by construction


def test_saved_team_actors_act_and_are_attacked_in_batches(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A constrained learner's saved actor (MAPPO/IPPO format): lockstep rows = lone rows."""
    import numpy as np

    from advgame.workflows import zoo

    actors = zoo.load("safetyhopper/pcrpo")
    policy = actors["protagonist"].build(_info("SafetyHopper-v5"))
    obs = np.random.default_rng(0).normal(size=(9, 11)) * 3
    assert policy.batch_key is not None
    assert np.array_equal(policy.act_batch(obs), np.stack([policy.act(o) for o in obs]))
    setups = {
        "nominal": AdversarySetup.nominal(),
        "mad": AdversarySetup({"preset": "default"}, {OBS: MADAttack(steps=3)}),
    }
    jobs = population_jobs("SafetyHopper-v5", {"pcrpo": actors}, setups, seeds=(0, 1, 2))
    sizes = _walk_sizes(monkeypatch)
    batched = evaluate(jobs, progress=False)
    assert max(sizes) == 3  # the three games' attacks in one walk
    alone = [row for unit in split_seeds(jobs, 1) for row in run_job(unit)]
    assert _rows(batched.rows) == _rows(alone)


def _info(scenario: str) -> Any:
    import advgame

    game = advgame.make(scenario, preset="default")
    info = game.agent_info("protagonist")
    game.close()
    return info
