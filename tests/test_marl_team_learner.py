"""Multi-agent protagonists, part two: the MAPPO/IPPO `TeamLearner`.

Its configs (the paper's defaults, documented and validated fields), the `Side` protocol the loop
drives (learn, freeze, seeded reproducibility, save/load round trips, saved specs in `rollout`,
learning against a learned adversary) and that both algorithms really learn MA-Hopper-3x1. Real
MuJoCo (MaMuJoCo), real torch and real Stable-Baselines3 throughout.
"""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import advgame
from advgame.adversaries import GaussianAdversary
from advgame.agents.common.checkpoint import SB3Policy
from advgame.agents.common.side import Side
from advgame.agents.common.stats import EpisodeStats
from advgame.agents.marl.marl import (
    MARL_LEARNERS,
    IPPOConfig,
    MAPPOConfig,
    TeamLearner,
    TeamPPOConfig,
)
from advgame.agents.marl.nets import TorchActorCheckpoint, TorchActorPolicy
from advgame.agents.sb3.config import PPOConfig
from advgame.core.config import field_docs
from advgame.core.episodes import rollout
from advgame.core.policy import ConstantPolicy
from advgame.core.team import team_factory
from advgame.core.views import view_factory
from advgame.errors import ConfigError
from tests._marl_helpers import SID, _assert_same, noisy

# like test_marl_team_view.py, the whole MARL suite needs the mamujoco extra
pytest.importorskip("supersuit", reason="the mamujoco extra: pip install '.[mamujoco]'")

pytestmark = pytest.mark.usefixtures("one_torch_thread")


# -- MAPPO / IPPO configs ---------------------------------------------------------------------------
PAPER = {  # Robust Gymnasium, appendix table "PPO, MAPPO and IPPO"
    "learning_rate": 3e-4,
    "lr_decay": True,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "net_arch": (64, 64),
    "n_steps": 2048,
    "n_epochs": 10,
    "batch_size": 64,
    "vf_coef": 0.25,
    "ent_coef": 0.0,
    "max_grad_norm": 0.5,
    "normalize_observations": True,
    "normalize_reward": True,
    "normalize_advantage": False,
}


@pytest.mark.parametrize("cls", [MAPPOConfig, IPPOConfig])
def test_configs_default_to_the_paper_table_and_document_every_field(cls: type) -> None:
    cfg = cls()
    assert {k: getattr(cfg, k) for k in PAPER} == PAPER
    assert MARL_LEARNERS[cls.algo] is cls and cls.centralised == (cls.algo == "mappo")
    names = {f.name for f in dataclasses.fields(cls)}
    assert names == set(field_docs(cls))
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.gamma = 0.5  # type: ignore[misc]


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("learning_rate", 0.0),
        ("gamma", 1.5),
        ("gae_lambda", -0.1),
        ("clip_range", 0.0),
        ("n_steps", 0),
        ("batch_size", 32.5),
        ("vf_coef", -1.0),
        ("net_arch", ()),
        ("net_arch", (64, 0)),
        ("max_grad_norm", 0.0),
        ("log_std_init", float("nan")),
    ],
)
def test_config_validation_names_the_bad_field(field: str, value: Any) -> None:
    with pytest.raises(ConfigError, match=field):
        MAPPOConfig(**{field: value})


def test_team_learner_needs_box_spaces_and_a_team_config() -> None:
    with pytest.raises(ConfigError, match="Box"):
        TeamLearner(IPPOConfig(), [team_factory("LunarLander-v3")], seed=0, total_steps=10)
    with pytest.raises(ConfigError, match="MAPPOConfig or IPPOConfig"):
        TeamLearner(TeamPPOConfig(), [team_factory(SID)], seed=0, total_steps=10)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="total_steps"):
        TeamLearner(IPPOConfig(), [team_factory(SID)], seed=0, total_steps=0)


# -- MAPPO / IPPO: the Side protocol ----------------------------------------------------------------
TINY = {"n_steps": 32, "batch_size": 32, "n_epochs": 2}


def tiny_learner(
    algo: str, seed: int = 0, n_envs: int = 2, tensorboard_log: str | None = None
) -> TeamLearner:
    fns = [team_factory(SID, preset="default", max_episode_steps=40) for _ in range(n_envs)]
    return TeamLearner(MARL_LEARNERS[algo](**TINY), fns, seed, 256, tensorboard_log)


def _parameters(learner: TeamLearner) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in learner.model.state_dict().items()}


class _Counter:
    """Stands in for the loop's tqdm bar: counts updates."""

    def __init__(self) -> None:
        self.n = 0

    def update(self, n: int) -> None:
        self.n += n


@pytest.mark.parametrize("algo", ["mappo", "ippo"])
def test_learn_trains_every_network_and_reports_true_team_returns(
    algo: str, tmp_path: Path
) -> None:
    learner = tiny_learner(algo, tensorboard_log=str(tmp_path))
    assert learner.agents == ["agent_0", "agent_1"]
    learner.set_policies({a: GaussianAdversary(std=0.05) for a in learner.envs[0].game.adversaries})
    before = _parameters(learner)
    stats = EpisodeStats(_Counter())
    learner.learn(100, stats)  # at least 100 steps: two rollouts of 32 steps x 2 views
    assert learner.steps == 128 and stats.progress.n == 128
    assert len(stats.true_returns) == 2  # each view finished one 40-step episode
    assert all(np.isfinite(stats.true_returns)) and len(set(stats.true_returns)) == 2
    after = _parameters(learner)
    unchanged = [k for k in before if torch.equal(before[k], after[k])]
    assert not unchanged, f"not trained: {unchanged}"
    critics = [k for k in after if k.startswith("critics.")]
    assert critics and all(k.startswith("critics.central") for k in critics) == (algo == "mappo")
    std = learner.observation_std()
    assert std is not None and {a: s.shape for a, s in std.items()} == {
        "agent_0": (12,),
        "agent_1": (12,),
    }
    learner.close()
    assert list((tmp_path / algo).glob("events.out.tfevents.*"))  # TensorBoard scalars


def test_freeze_stops_the_normalizers_until_learn() -> None:
    learner = tiny_learner("mappo", n_envs=1)
    learner.learn(32)
    learner.freeze()
    frozen = learner.observation_std()
    learner.collector.collect(learner.model, learner.generator, None)  # frozen: stats stay put
    assert all(np.array_equal(frozen[a], s) for a, s in learner.observation_std().items())
    learner.learn(32)
    assert not np.array_equal(frozen["agent_0"], learner.observation_std()["agent_0"])
    learner.close()


@pytest.mark.parametrize("algo", ["mappo", "ippo"])
def test_a_seeded_run_reproduces_exactly(algo: str) -> None:
    runs = []
    for seed in (5, 5, 6):
        learner = tiny_learner(algo, seed=seed)
        learner.set_policies({"observation_adversary": GaussianAdversary(std=0.05)})
        stats = EpisodeStats()
        learner.learn(128, stats)
        runs.append((_parameters(learner), stats.true_returns, learner.optimizer.state_dict()))
        learner.close()
    (p1, r1, o1), (p2, r2, o2), (p3, _, _) = runs
    assert p1.keys() == p2.keys() and all(torch.equal(p1[k], p2[k]) for k in p1)
    assert r1 == r2
    assert all(
        torch.equal(o1["state"][i]["exp_avg"], o2["state"][i]["exp_avg"]) for i in o1["state"]
    )
    assert not all(torch.equal(p1[k], p3[k]) for k in p1)  # another seed, another run


@pytest.mark.parametrize("algo", ["mappo", "ippo"])
def test_save_load_round_trip_gives_identical_actions(algo: str, tmp_path: Path) -> None:
    learner = tiny_learner(algo)
    learner.learn(64)
    specs = learner.save(tmp_path)
    assert set(specs) == {"agent_0", "agent_1"}
    assert specs["agent_1"] == TorchActorCheckpoint(str(tmp_path / f"{algo}_actors.pt"), "agent_1")
    spec = pickle.loads(pickle.dumps(specs["agent_1"]))
    game = learner.envs[0].game
    policy = spec.build(game.agent_info("agent_1"))
    assert isinstance(policy, TorchActorPolicy)
    resumed = TeamLearner.load(tmp_path, MARL_LEARNERS[algo](**TINY), [team_factory(SID)] * 2)
    assert resumed.steps == learner.steps == 64
    assert all(
        torch.equal(v, resumed.model.state_dict()[k]) for k, v in learner.model.state_dict().items()
    )
    rng = np.random.default_rng(0)
    for _ in range(10):
        obs = {a: rng.normal(0, 2, 12) for a in learner.agents}
        expected = learner.predict(obs)
        np.testing.assert_array_equal(policy.act(obs["agent_1"]), expected["agent_1"])
        _assert_same(resumed.predict(obs), expected)
    assert resumed.rng.bit_generator.state == learner.rng.bit_generator.state
    assert torch.equal(resumed.generator.get_state(), learner.generator.get_state())
    resumed.learn(64)  # and it trains on
    assert resumed.steps == 128
    with pytest.raises(ConfigError, match="no actor for 'agent_7'"):
        TorchActorCheckpoint(spec.path, "agent_7").build(game.agent_info("agent_1"))
    hopper = advgame.make("MA-Hopper-3x1")
    with pytest.raises(ConfigError, match="observes"):
        spec.build(hopper.agent_info("agent_1"))
    for v in (learner, resumed):
        v.close()


def test_saved_specs_play_in_rollout_against_adversaries(tmp_path: Path) -> None:
    learner = tiny_learner("ippo")
    learner.learn(64)
    game = advgame.make(SID, preset="default", max_episode_steps=40)
    for deterministic in (True, False):
        specs = learner.save(tmp_path / str(deterministic), deterministic=deterministic)
        policies = {**specs, **noisy(game, std=0.1)}
        first = rollout(game, policies, seed=3, episodes=2)
        again = rollout(game, policies, seed=3, episodes=2)
        assert first == again  # seeded: the stochastic actors reseed per episode too
        assert [r.length for r in first] == [40, 40]
        assert first[0].true_return != first[1].true_return
    learner.close()


def test_learn_against_a_learned_adversary_spec(tmp_path: Path) -> None:
    """One alternation by hand: team phase, an SB3 adversary phase, the team again vs it."""
    learner = tiny_learner("mappo")
    learner.learn(64)
    frozen = learner.save(tmp_path / "team", deterministic=False)
    adversary = Side(
        "observation_adversary",
        PPOConfig(n_steps=64, batch_size=32, n_epochs=2),
        [
            view_factory(
                SID, "observation_adversary", frozen, preset="default", max_episode_steps=40
            )
        ],
        seed=0,
        total_steps=128,
    )
    adversary.learn(128)
    spec = adversary.save(tmp_path / "adversary", deterministic=False)
    adversary.close()
    learner.set_policies({"observation_adversary": spec}, index=1)
    assert isinstance(learner.envs[1].policies["observation_adversary"], SB3Policy)
    assert isinstance(learner.envs[0].policies["observation_adversary"], ConstantPolicy)
    learner.set_policies({"observation_adversary": spec})
    stats = EpisodeStats()
    learner.learn(64, stats)
    assert learner.steps == 128 and all(np.isfinite(stats.true_returns))
    std = learner.observation_std()
    assert std is not None
    for agent, s in std.items():  # what the loop pushes into normalized-space budgets
        learner.set_observation_scale(agent, s)
    learner.close()


# -- MAPPO / IPPO learn -----------------------------------------------------------------------------
LEARN_SID = "MA-Hopper-3x1"  # three heterogeneous agents (8, 9, 8 observations), one joint each
LEARN_STEPS = 8192
LEARN_CONFIG = {
    "n_steps": 256,
    "n_epochs": 5,
    "batch_size": 128,
    "learning_rate": 1e-3,
    "lr_decay": False,
}
# Measured with exactly this test (2 views, nominal game), seeds 0-7 of each algorithm: the
# stochastic policy's mean true team return over the same 10 seeded evaluation episodes was
# 15.0-15.4 before training (uniformly random actions: 23); after 8192 steps it was MAPPO
# 153-293 and IPPO 209-811, and the last five training episodes averaged MAPPO 132-288, IPPO
# 207-326. Both thresholds sit well clear of both ends (5x the random return, 0.6x the worst
# trained one); seed 0, used here, is MAPPO's slowest learner of the eight.
RANDOM_AT_MOST = 40.0
TRAINED_AT_LEAST = 80.0


@pytest.mark.parametrize("algo", ["mappo", "ippo"])
def test_learner_learns_to_hop(algo: str, tmp_path: Path) -> None:
    fns = [team_factory(LEARN_SID, disruptors=[]) for _ in range(2)]
    learner = TeamLearner(MARL_LEARNERS[algo](**LEARN_CONFIG), fns, seed=0, total_steps=LEARN_STEPS)
    game = advgame.make(LEARN_SID, disruptors=[])

    def score(tag: str) -> float:
        specs = learner.save(tmp_path / tag, deterministic=False)
        return float(np.mean([r.true_return for r in rollout(game, specs, seed=100, episodes=10)]))

    before = score("before")
    stats = EpisodeStats()
    learner.learn(LEARN_STEPS, stats)
    after = score("after")
    assert before < RANDOM_AT_MOST, before
    assert after > TRAINED_AT_LEAST, (before, after)
    assert np.mean(stats.true_returns[-5:]) > TRAINED_AT_LEAST, stats.true_returns[-5:]
    learner.close()


def test_a_resumed_team_learner_goes_on_with_its_shifting_task(tmp_path: Path) -> None:
    from advgame.adversaries import SinusoidAdversary

    adversary = advgame.make(SID, preset="default").adversaries[0]
    wave = {adversary: SinusoidAdversary(0.0, 0.01, 0.5, start=1)}

    def fns() -> list[Any]:
        return [team_factory(SID, wave, preset="default", max_episode_steps=40) for _ in range(2)]

    learner = TeamLearner(MARL_LEARNERS["mappo"](**TINY), fns(), 0, 512)
    learner.learn(256)  # episodes of 40 steps: several finished in each view
    saved = [env.schedule_positions() for env in learner.envs]
    assert all(p[adversary] > 2 for p in saved), saved
    learner.save(tmp_path)
    resumed = TeamLearner.load(tmp_path, MARL_LEARNERS["mappo"](**TINY), fns())
    for env, where in zip(resumed.envs, saved, strict=True):
        env.reset(seed=1)  # the next episode is the one after the saved one, not episode 1
        assert env.schedule_positions() == {adversary: where[adversary] + 1}
