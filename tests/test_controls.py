"""Controls (issue 68): each comparison's SAC shares its method's settings; the ablations ablate.

A matched SAC must learn with the networks, batch, returns, step sizes, temperature, start
steps and update schedule of the method it stands beside (checked against the method's own
config, so a changed default shows here); `MatchedSAC` with its defaults must be SB3's SAC
bit for bit, and with an actor interval of k must step the actor once per k updates; the
OMPO ablations must change the reward correction and nothing else, and log its size.
"""

from __future__ import annotations

import gymnasium as gym
import pytest
import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.vec_env import DummyVecEnv

from advgame.agents import DBCConfig, OMPOConfig, RSCConfig, SACConfig
from advgame.agents.ompo.nets import OMPOPolicy
from advgame.errors import ConfigError
from advgame.training import METHODS, learner_config

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SHARED = ("learning_rate", "net_arch", "learning_starts", "batch_size", "ent_coef",
          "gradient_steps", "tau", "gamma", "buffer_size", "lr_decay")  # fmt: skip


def _control(method: str) -> SACConfig:
    entry = METHODS[method]
    assert entry["protagonist_algo"] == "sac" and entry["normalize"] is False
    return learner_config("sac", entry["protagonist_hparams"])


@pytest.mark.parametrize(
    ("control", "method", "config"),
    [("sac-rsc-matched", "rsc", RSCConfig()), ("sac-dbc-matched", "dbc", DBCConfig()),
     ("sac-ompo-matched", "ompo", OMPOConfig())],
)  # fmt: skip
def test_each_matched_sac_shares_its_method_s_settings(control, method, config) -> None:
    sac = _control(control)
    for name in SHARED:
        assert getattr(sac, name) == getattr(config, name), name
    assert METHODS[method]["normalize"] is False  # both on raw observations and rewards
    own_critic_rate = getattr(config, "critic_learning_rate", None)
    assert sac.critic_learning_rate == own_critic_rate
    assert sac.n_steps == getattr(config, "n_steps", 1)
    interval = {"rsc": 1, "dbc": getattr(config, "actor_update_interval", 0),
                "ompo": getattr(config, "target_update_interval", 0)}[method]  # fmt: skip
    assert sac.actor_update_interval == interval
    assert sac.networks == ("ompo" if method == "ompo" else "sb3")


def test_the_ablations_change_one_field_of_their_method() -> None:
    assert learner_config("rsc", METHODS["rsc-noaug"]["protagonist_hparams"]) == RSCConfig(
        augmented_ratio=0.0
    )
    nocorr = learner_config("ompo", METHODS["ompo-nocorr"]["protagonist_hparams"])
    corr = learner_config("ompo", METHODS["ompo-corr10"]["protagonist_hparams"])
    assert nocorr == OMPOConfig(correction_weight=0.0) and nocorr.tomac_alpha == 1e-3
    assert corr.correction_weight == 0.75


def _env() -> DummyVecEnv:
    return DummyVecEnv([lambda: gym.make("InvertedPendulum-v5")])


def _small(**kwargs) -> SACConfig:
    return SACConfig(net_arch=(16, 16), learning_starts=30, batch_size=16, **kwargs)


def test_matched_sac_with_its_defaults_is_sb3_s_sac_bit_for_bit() -> None:
    mine = _small().make_model(_env(), seed=3, total_steps=100)
    mine.learn(80)  # (one model at a time: SB3 seeds torch's global generator)
    theirs = SAC("MlpPolicy", _env(), **{
        "learning_starts": 30, "batch_size": 16, "ent_coef": 0.2, "learning_rate": 1e-3,
        "seed": 3, "device": "cpu", "policy_kwargs": {
            "net_arch": [16, 16], "optimizer_kwargs": {"foreach": True}}})  # fmt: skip
    theirs.learn(80)
    a, b = mine.policy.state_dict(), theirs.policy.state_dict()
    assert a.keys() == b.keys()
    for name in a:
        assert th.equal(a[name], b[name]), name


def test_the_actor_learns_every_kth_update_and_the_critic_at_its_own_rate() -> None:
    model = _small(actor_update_interval=2, critic_learning_rate=2e-3, ent_coef="auto_0.1",
                   learning_rate=3e-4).make_model(_env(), seed=0, total_steps=100)  # fmt: skip
    steps = {"actor": 0, "critic": 0, "alpha": 0}
    for key, opt in (("actor", model.actor.optimizer), ("critic", model.critic.optimizer),
                     ("alpha", model.ent_coef_optimizer)):  # fmt: skip
        original = opt.step

        def counted(*args, _k=key, _step=original, **kwargs):
            steps[_k] += 1
            return _step(*args, **kwargs)

        opt.step = counted
    model.learn(71)
    updates = 71 - 30  # one per step once past learning_starts
    assert model._n_updates == steps["critic"] == updates
    assert steps["actor"] == steps["alpha"] == (updates + 1) // 2
    assert model.critic.optimizer.param_groups[0]["lr"] == 2e-3
    assert model.actor.optimizer.param_groups[0]["lr"] == 3e-4


def test_n_step_returns_and_ompo_s_networks_reach_the_model(tmp_path) -> None:
    model = _small(n_steps=4, networks="ompo").make_model(_env(), seed=0, total_steps=100)
    assert isinstance(model.replay_buffer, NStepReplayBuffer) and model.n_steps == 4
    assert isinstance(model.policy, OMPOPolicy)
    model.learn(40)
    model.save(tmp_path / "m.zip")
    back = SACConfig.model_class().load(tmp_path / "m.zip", device="cpu")  # a resume's class
    assert back.actor_update_interval == 1 and isinstance(back.policy, OMPOPolicy)


@pytest.mark.parametrize(
    ("fields", "match"),
    [({"ent_coef": "fixed"}, "ent_coef"), ({"n_steps": 0}, "n_steps"),
     ({"actor_update_interval": 0}, "actor_update_interval"), ({"networks": "big"}, "networks"),
     ({"critic_learning_rate": -1.0}, "critic_learning_rate")],
)  # fmt: skip
def test_bad_matched_fields_are_clear_errors(fields, match) -> None:
    with pytest.raises(ConfigError, match=match):
        SACConfig(**fields)
    with pytest.raises(ConfigError, match="correction_weight"):
        OMPOConfig(correction_weight=-1.0)


def _ompo(**kwargs):
    options = {"learning_starts": 50, "batch_size": 16, "local_size": 40, "disc_batch": 8}
    return OMPOConfig(net_arch=(16, 16), **options, **kwargs).make_model(
        _env(), seed=0, total_steps=1000
    )


def test_the_correction_weight_changes_the_reward_correction_alone() -> None:
    from stable_baselines3.common.type_aliases import ReplayBufferSamples

    g = th.Generator().manual_seed(0)
    obs, nxt, act = th.randn(8, 4, generator=g), th.randn(8, 4, generator=g), th.rand(8, 1)
    data = ReplayBufferSamples(obs, act, nxt, th.zeros(8, 1), th.randn(8, 1, generator=g))
    off, big = _ompo(correction_weight=0.0), _ompo(correction_weight=0.5)
    big.discriminator.load_state_dict(off.discriminator.state_dict())
    base = th.clamp(data.rewards + 1.0, min=1e-6)
    logit = off.discriminator.trunk(th.cat([obs, act, nxt], 1)).detach()
    assert th.equal(off.shaped_reward(data), base)
    assert th.allclose(big.shaped_reward(data), base - 0.5 * logit)
    assert off.tomac_alpha == big.tomac_alpha == 1e-3  # the initial-state term keeps its weight


def test_the_correction_s_size_is_logged_per_update(tmp_path) -> None:
    from stable_baselines3.common.logger import configure

    model = _ompo(correction_weight=0.5)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(130, log_interval=1)
    import csv

    rows = [r for r in csv.DictReader((tmp_path / "progress.csv").open()) if r["train/logit_abs"]]
    assert rows
    for r in rows:
        logit, corr, ratio = (float(r[f"train/{k}"]) for k in ("logit_abs", "correction_abs",
                                                                 "correction_ratio"))  # fmt: skip
        assert logit > 0 and corr == pytest.approx(0.5 * logit)
        # InvertedPendulum pays 1 a step (0 as it falls): the shifted reward is 2 (or 1)
        assert corr / 2.0 <= ratio < corr / 1.5
