"""`advgame.core.vector.VectorView`: N views in lockstep play exactly the N single views' episodes.

The reference is a `DummyVecEnv` of the same `SingleAgentView`s (each view its own game and
policies, seeded ``s + i``): every observation, reward, done and info (true reward, cost,
payoff, clip counts, ``terminal_observation``) must be equal, across autoresets and
per-episode dynamics shifts, while frozen SB3 networks are asked once per move for all views.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecCheckNan

import advgame
from advgame import adversaries as adv
from advgame.agents.common.checkpoint import SB3Checkpoint, SB3Policy
from advgame.core.policy import act_batch
from advgame.core.vector import VectorView
from advgame.core.views import view_factory
from advgame.errors import ConfigError

N = 3


def _same(a: Any, b: Any, where: str) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, list | tuple) or (isinstance(a, np.ndarray) and a.dtype == object):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b, err_msg=where, strict=True)
    else:
        assert a == b, (where, a, b)


def _play_both(fns: list[Callable[[], Any]], steps: int, seed: int, scale: float = 1.0) -> int:
    """Step a VectorView and a DummyVecEnv of the same views side by side; return resets seen."""
    vec, ref = VectorView(fns), DummyVecEnv(fns)
    vec.seed(seed)
    ref.seed(seed)
    _same(vec.reset(), ref.reset(), "reset")
    _same(vec.reset_infos, ref.reset_infos, "reset infos")
    rng = np.random.default_rng(seed)
    space = vec.action_space
    dones = 0
    for t in range(steps):
        actions = (rng.normal(size=(N, *space.shape)) * scale).astype(space.dtype)
        got, want = vec.step(actions), ref.step(actions)
        for name, x, y in zip(("obs", "reward", "done", "infos"), got, want, strict=True):
            _same(x, y, f"step {t} {name}")
        dones += int(got[2].sum())
    vec.close()
    ref.close()
    return dones


def test_protagonist_views_in_lockstep_play_the_single_views_episodes() -> None:
    # every disruptor kind at once: sense-time observation noise, reward and action noise,
    # forces, and a per-episode dynamics shift that each view restores on its own resets
    game = advgame.make("Hopper-v5", preset="full")
    policies: dict[str, Any] = {a: adv.GaussianAdversary(std=0.05) for a in game.adversaries}
    policies["dynamics_adversary"] = adv.UniformAdversary(0.8, 1.2)
    game.close()
    fns = [view_factory("Hopper-v5", "protagonist", policies, preset="full") for _ in range(N)]
    assert _play_both(fns, 150, seed=3) >= 2 * N  # random actions: several autoresets each


def test_views_of_other_set_ups_step_game_by_game_and_still_play_their_own_episodes() -> None:
    noise = {"observation_adversary": adv.GaussianAdversary(std=0.1)}
    fns = [
        view_factory("Hopper-v5", "protagonist", noise, preset="state-gauss-0.1"),
        view_factory("Hopper-v5", "protagonist", noise, preset="default"),
        view_factory("Hopper-v5", "protagonist", noise, preset="state-gauss-0.1"),
    ]
    assert not VectorView(fns)._alike  # two set-ups: no batched move, one lockstep loop
    assert _play_both(fns, 100, seed=11) >= N


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory: pytest.TempPathFactory) -> SB3Checkpoint:
    """An (untrained, deterministic) PPO Hopper protagonist saved as a checkpoint."""
    path = tmp_path_factory.mktemp("ppo") / "protagonist.zip"
    PPO("MlpPolicy", gym.make("Hopper-v5"), seed=0, device="cpu").save(path)
    return SB3Checkpoint(str(path), "ppo")


def test_the_gymnasium_face_plays_what_sync_vector_env_plays_with_the_same_views() -> None:
    from gymnasium.vector import SyncVectorEnv

    from advgame.core.vector import GymVectorView

    noise = {"observation_adversary": adv.GaussianAdversary(std=0.1)}
    fns = [view_factory("Hopper-v5", "protagonist", noise, preset="state-gauss-0.1")] * N
    mine, ref = GymVectorView(fns), SyncVectorEnv(fns, autoreset_mode="SameStep")
    _same(mine.reset(seed=7), ref.reset(seed=7), "reset")
    rng, finals = np.random.default_rng(0), 0
    for t in range(80):
        actions = rng.uniform(-1, 1, size=(N, 3)).astype(np.float32)
        got, want = mine.step(actions), ref.step(actions)
        for name, x, y in zip(("obs", "reward", "term", "trunc", "infos"), got, want, strict=True):
            _same(x, y, f"step {t} {name}")
        finals += int(got[2].sum())
    assert finals >= N  # episodes ended and were reset in the same step
    mine.close()
    ref.close()


def test_adversary_views_batch_the_frozen_protagonist_and_count_clips_per_view(
    checkpoint: SB3Checkpoint, monkeypatch: pytest.MonkeyPatch, one_torch_thread: None
) -> None:
    calls: list[int] = []
    batch = SB3Policy.act_batch

    def spy(self: SB3Policy, observations: Any) -> Any:
        calls.append(len(observations))
        return batch(self, observations)

    monkeypatch.setattr(SB3Policy, "act_batch", spy)
    policies = {"protagonist": checkpoint, "action_adversary": adv.GaussianAdversary(std=0.1)}
    fns = [
        view_factory("Hopper-v5", "observation_adversary", policies, preset="default")
        for _ in range(N)
    ]
    # actions of scale 2 leave the [-1, 1] budget box: clips happen and are counted per view
    assert _play_both(fns, 120, seed=5, scale=2.0) >= N
    assert calls and max(calls) == N  # one forward pass for all views in lockstep


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_a_batched_forward_pass_gives_each_row_the_single_row_action(algo: str) -> None:
    from advgame.agents.common.checkpoint import _algo_class

    model = _algo_class(algo)("MlpPolicy", gym.make("Hopper-v5"), seed=0, device="cpu")
    rng = np.random.default_rng(0)
    policy = SB3Policy(model, rng.normal(size=11), rng.uniform(0.5, 2.0, size=11))
    obs = rng.normal(size=(17, 11))
    rows = np.stack([policy.act(o) for o in obs])
    np.testing.assert_array_equal(policy.act_batch(obs), rows)
    # ... and every single-row action is SB3's own deterministic `predict`
    for o, row in zip(obs, rows, strict=True):
        norm = np.clip((o - policy.mean) / policy.std, -10, 10).astype(np.float32)
        np.testing.assert_array_equal(row, model.predict(norm, deterministic=True)[0])
    assert policy.batch_key is not None
    sampling = SB3Policy(model, deterministic=False).batch_key
    # only a PPO Gaussian samples in batches (the training loop's frozen opponents)
    assert (sampling is not None) == (algo == "ppo") and sampling != policy.batch_key


def test_a_sampling_ppo_policy_draws_a_batch_from_its_own_distribution(
    one_torch_thread: None,
) -> None:
    import torch

    model = PPO("MlpPolicy", gym.make("Hopper-v5"), seed=0, device="cpu")
    policy = SB3Policy(model, deterministic=False)
    obs = np.random.default_rng(0).normal(size=11)
    torch.manual_seed(0)
    batch = policy.act_batch(np.tile(obs, (4000, 1)))
    one_by_one = np.stack([policy.act(obs) for _ in range(4000)])
    for seed in range(3):  # one row is SB3's own sample, draw for draw
        torch.manual_seed(seed)
        mine = policy.act(obs)
        torch.manual_seed(seed)
        np.testing.assert_array_equal(mine, model.predict(obs.astype(np.float32))[0])
    assert batch.shape == one_by_one.shape and np.unique(batch[:, 0]).size > 1000
    assert np.abs(batch).max() <= 1.0  # clipped into the action box as SB3 does
    np.testing.assert_allclose(batch.mean(0), one_by_one.mean(0), atol=0.06)
    np.testing.assert_allclose(batch.std(0), one_by_one.std(0), atol=0.06)


def test_act_batch_asks_policies_without_a_common_key_one_by_one() -> None:
    game = advgame.make("Hopper-v5", preset="state-gauss-0.1")
    info = game.agent_info("observation_adversary")
    pols = [adv.GaussianAdversary(std=0.1).build(info) for _ in range(3)]
    for i, p in enumerate(pols):
        p.reset(seed=i)
    got = act_batch(pols, [None] * 3)
    for i, p in enumerate(pols):  # each policy kept its own stream
        p.reset(seed=i)
        np.testing.assert_array_equal(got[i], p.act(None))
    assert not np.array_equal(got[0], got[1])
    game.close()


def test_sb3_wrappers_and_ppo_learn_on_vector_views_of_both_sides(one_torch_thread: None) -> None:
    from advgame.agents import PPOConfig
    from advgame.agents.common.side import Side
    from advgame.agents.common.stats import EpisodeStats

    noise = {"observation_adversary": adv.GaussianAdversary(std=0.1)}
    for agent, policies, preset in (
        ("protagonist", noise, "state-gauss-0.1"),
        ("observation_adversary", {"protagonist": _zero}, "default"),  # a bounded budget
    ):
        fns = [view_factory("Hopper-v5", agent, policies, preset=preset)] * 2
        learner = PPOConfig(n_steps=64, batch_size=32, n_epochs=1)
        side = Side(agent, learner, fns, seed=0, total_steps=256)
        assert isinstance(side.venv.venv, VectorView)
        before = {k: v.clone() for k, v in side.model.policy.state_dict().items()}
        stats = EpisodeStats()
        side.learn(256, stats)
        assert side.steps >= 256
        after = side.model.policy.state_dict()
        assert any(not before[k].equal(after[k]) for k in before)
        side.close()
    nan_checked = VecCheckNan(VectorView(fns), raise_exception=True)
    nan_checked.reset()
    PPO("MlpPolicy", nan_checked, n_steps=32, batch_size=32, n_epochs=1, device="cpu").learn(64)


def test_a_vector_view_refuses_envs_that_are_not_views_of_one_agent() -> None:
    with pytest.raises(ConfigError, match="SingleAgentViews of one agent"):
        VectorView([lambda: gym.make("Hopper-v5")])
    mixed = [
        view_factory("Hopper-v5", "protagonist", preset="default"),
        view_factory(
            "Hopper-v5", "observation_adversary", {"protagonist": _zero}, preset="default"
        ),
    ]
    with pytest.raises(ConfigError, match="of agents"):
        VectorView(mixed)


def _zero(obs: Any) -> np.ndarray:
    return np.zeros(3, dtype=np.float32)


def _zero_action(obs: Any) -> np.ndarray:
    return np.zeros(3, dtype=np.float32)  # the action adversary's no-op in preset "default"


def test_checkpoint_views_share_one_network_in_process(checkpoint: SB3Checkpoint) -> None:
    fns = [view_factory("Hopper-v5", "observation_adversary", {"protagonist": checkpoint})] * 2
    venv = VectorView(fns)
    keys = {v.policies["protagonist"].batch_key for v in venv.envs}
    assert len(keys) == 1 and None not in keys
    venv.close()


# -- batched evaluation ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def adversary_checkpoint(tmp_path_factory: pytest.TempPathFactory) -> SB3Checkpoint:
    """An (untrained, deterministic) PPO observation adversary of preset ``default``."""
    view = view_factory(
        "Hopper-v5", "observation_adversary", {"protagonist": _zero}, preset="default"
    )()
    path = tmp_path_factory.mktemp("adv") / "observation_adversary.zip"
    PPO("MlpPolicy", view, seed=1, device="cpu").save(path)
    return SB3Checkpoint(str(path), "ppo")


def test_batched_evaluation_rows_equal_the_per_episode_path(
    checkpoint: SB3Checkpoint,
    adversary_checkpoint: SB3Checkpoint,
    monkeypatch: pytest.MonkeyPatch,
    one_torch_thread: None,
) -> None:
    from advgame.evaluation import AdversarySetup, population_jobs, run_job
    from advgame.evaluation.table.batched import play_job_sequential

    protagonists = {"ppo": checkpoint, "zero": _zero}
    setups = {
        "nominal": AdversarySetup.nominal(),
        "gauss": AdversarySetup.from_preset("Hopper-v5", "state-gauss-0.1"),
        "shift": AdversarySetup.from_preset("Hopper-v5", "shift-uniform"),
        "learned": AdversarySetup(
            {"preset": "default"},
            {"observation_adversary": adversary_checkpoint, "action_adversary": _zero_action},
        ),
    }
    jobs = population_jobs("Hopper-v5", protagonists, setups, seeds=(0, 2, 5), episodes=2)
    calls: list[int] = []
    batch = SB3Policy.act_batch
    monkeypatch.setattr(SB3Policy, "act_batch", lambda s, o: calls.append(len(o)) or batch(s, o))
    for job in jobs:
        got, want = run_job(job), play_job_sequential(job)
        assert len(got) == 6
        _same(got, want, f"{job.protagonist} vs {job.adversary}")
    assert max(calls) == 6  # the six episodes of a job asked the network together
