"""Evaluation batched across jobs: a whole table in lockstep gives the per-episode path's rows.

Real Hopper games, real (untrained, deterministic) SB3 PPO networks as protagonists and as a
learned adversary, Gaussian noise and dynamics shifts; every row of a table played by
`evaluate` in this process (groups of jobs in lockstep, `play_jobs`) is compared value for
value with `play_job_sequential` run job by job.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO

from advgame.agents.common.checkpoint import SB3Checkpoint, SB3Policy
from advgame.core.views import view_factory
from advgame.errors import ConfigError
from advgame.evaluation import (
    AdversarySetup,
    EvalJob,
    evaluate,
    lockstep_groups,
    population_jobs,
)
from advgame.evaluation.table.batched import play_job_sequential, play_jobs

ENV = "Hopper-v5"


def _zero(obs: Any) -> np.ndarray:
    return np.zeros(3, dtype=np.float32)


def _ppo(env: Any, seed: int, path: Any) -> SB3Checkpoint:
    PPO("MlpPolicy", env, seed=seed, device="cpu").save(path)
    return SB3Checkpoint(str(path), "ppo")


@pytest.fixture(scope="module")
def jobs(tmp_path_factory: pytest.TempPathFactory) -> list[EvalJob]:
    """Two SB3 protagonists and a plain function × five columns × two seeds × two episodes."""
    folder = tmp_path_factory.mktemp("batched")
    protagonists = {
        "ppo0": _ppo(gym.make(ENV), 0, folder / "p0.zip"),
        "ppo1": _ppo(gym.make(ENV), 1, folder / "p1.zip"),
        "zero": _zero,
    }
    view = view_factory(ENV, "observation_adversary", {"protagonist": _zero}, preset="default")
    learned = _ppo(view(), 2, folder / "adv.zip")
    setups = {
        "nominal": AdversarySetup.nominal(),
        "gauss": AdversarySetup.from_preset(ENV, "state-gauss-0.1"),
        "action-gauss": AdversarySetup.from_preset(ENV, "action-gauss-0.1"),
        "shift": AdversarySetup.from_preset(ENV, "shift-uniform"),
        "learned": AdversarySetup({"preset": "default"}, {"observation_adversary": learned}),
    }
    return population_jobs(ENV, protagonists, setups, seeds=(0, 3), episodes=2)


def _same(got: list[dict[str, Any]], want: list[dict[str, Any]]) -> None:
    assert len(got) == len(want)
    for i, (a, b) in enumerate(zip(got, want, strict=True)):
        assert a.keys() == b.keys(), i
        for k in a:
            assert a[k] == b[k], (i, k, a[k], b[k], a["protagonist"], a["adversary"])


def test_a_table_in_lockstep_gives_the_per_episode_rows(
    jobs: list[EvalJob], monkeypatch: pytest.MonkeyPatch, one_torch_thread: None
) -> None:
    want = [row for job in jobs for row in play_job_sequential(job)]
    calls: list[int] = []
    batch = SB3Policy.act_batch
    monkeypatch.setattr(SB3Policy, "act_batch", lambda s, o: calls.append(len(o)) or batch(s, o))
    got = evaluate(jobs, workers=1, progress=False).rows
    _same(got, want)
    assert len({row["length"] for row in got}) > 3  # episodes of different lengths
    nominal = [r["true_return"] for r in got if r["adversary"] == "nominal"]
    assert nominal != [r["true_return"] for r in got if r["adversary"] == "learned"]
    # one protagonist network asked once per move for its 5 columns x 2 seeds x 2 episodes
    assert max(calls) == 20
    # the learned adversary asked for the games of all three protagonists at once
    assert 12 in calls
    again = evaluate(jobs, workers=1, progress=False).rows  # kept games, reset afresh
    _same(again, want)


def test_groups_of_jobs_split_anywhere_give_the_same_rows(
    jobs: list[EvalJob], one_torch_thread: None
) -> None:
    whole = [row for rows in play_jobs(jobs) for row in rows]
    for size in (1, 7):
        parts = [row for g in lockstep_groups(jobs, size) for rows in play_jobs(g) for row in rows]
        _same(parts, whole)


def test_lockstep_groups_keep_job_order_and_reject_bad_sizes(jobs: list[EvalJob]) -> None:
    groups = lockstep_groups(jobs, episodes=9)
    assert [j for g in groups for j in g] == jobs
    assert all(sum(len(j.seeds) * j.episodes for j in g) <= 9 for g in groups)
    assert [len(g) for g in lockstep_groups(jobs, episodes=1)] == [1] * len(jobs)
    with pytest.raises(ConfigError, match="episodes must be an int >= 1"):
        lockstep_groups(jobs, episodes=0)


def test_jobs_with_a_sampling_policy_are_played_alone(
    jobs: list[EvalJob], one_torch_thread: None
) -> None:
    import dataclasses

    spec = jobs[0].protagonist_spec
    sampling = dataclasses.replace(spec, deterministic=False)
    alone = [dataclasses.replace(j, protagonist_spec=sampling, seeds=(j.seeds[0],), episodes=1)
             for j in jobs[:4]]  # fmt: skip
    want = [row for job in alone for row in play_job_sequential(job)]
    _same([row for rows in play_jobs(alone) for row in rows], want)
