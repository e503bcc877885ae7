"""Recurrent (LSTM) protagonists and adversaries: sb3-contrib's RecurrentPPO in the loop.

An outside RecurrentPPO plays bit for bit as in plain sb3-contrib; the memory is carried across
the steps of an episode and zeroed at its start in views, batched evaluation and lockstep play;
``--method atla-lstm`` trains, resumes and is evaluated from the CLI.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

import advgame
from advgame.agents import LEARNERS, PPOConfig
from advgame.agents.common.checkpoint import SB3Checkpoint, load_model, saved_recurrent
from advgame.agents.common.recurrent_policy import RecurrentSB3Policy
from advgame.agents.recurrent.config import RecurrentPPOConfig
from advgame.cli import main
from advgame.core.episodes import build_policies, rollout, rollout_batch
from advgame.core.policy import AgentInfo
from advgame.errors import ConfigError
from advgame.evaluation import SEED_STRIDE
from advgame.training import METHODS, TrainConfig

TINY = ["--iterations", "2", "--protagonist-steps", "128", "--adversary-steps", "128"]
TINY += ["--set", 'protagonist_hparams={"n_steps": 64, "batch_size": 32, "lstm_hidden_size": 16}']
TINY += ["--set", 'adversary_hparams={"n_steps": 64, "batch_size": 32, "lstm_hidden_size": 16}']
TINY += ["--no-progress"]


def rows(folder: Path) -> list[dict[str, str]]:
    with (folder / "payoff.csv").open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def outside(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A RecurrentPPO + VecNormalize trained a little with plain sb3-contrib on Hopper-v5."""
    from sb3_contrib import RecurrentPPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp("outside")
    venv = VecNormalize(DummyVecEnv([lambda: gym.make("Hopper-v5")]), gamma=0.99)
    venv.seed(0)
    model = RecurrentPPO(
        "MlpLstmPolicy", venv, n_steps=128, batch_size=64, n_epochs=2, seed=0, device="cpu",
        policy_kwargs={"lstm_hidden_size": 16},
    )  # fmt: skip
    model.learn(512)
    model.save(folder / "model.zip")
    venv.save(str(folder / "vecnormalize.pkl"))
    venv.close()
    return folder


def plain_episodes(folder: Path, seeds: list[int]) -> list[float]:
    """The episodes as a plain sb3-contrib user plays them: state and episode starts by hand."""
    from sb3_contrib import RecurrentPPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    model = RecurrentPPO.load(folder / "model.zip", device="cpu")
    norm = VecNormalize.load(
        str(folder / "vecnormalize.pkl"), DummyVecEnv([lambda: gym.make("Hopper-v5")])
    )
    norm.training = False
    env, out = gym.make("Hopper-v5"), []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        state, start, total, done = None, np.ones((1,), dtype=bool), 0.0, False
        while not done:
            action, state = model.predict(
                norm.normalize_obs(obs)[None], state=state, episode_start=start, deterministic=True
            )
            start = np.zeros((1,), dtype=bool)
            obs, reward, terminated, truncated, _ = env.step(action[0])
            total += float(reward)
            done = terminated or truncated
        out.append(total)
    return out


def protagonist_of(folder: Path, game: advgame.Game) -> RecurrentSB3Policy:
    spec = SB3Checkpoint(
        str(folder / "model.zip"), "recurrent-ppo", str(folder / "vecnormalize.pkl")
    )
    policy = build_policies(game, {"protagonist": spec})["protagonist"]
    assert isinstance(policy, RecurrentSB3Policy)
    return policy


def test_an_outside_recurrent_ppo_plays_bit_for_bit_through_advgame_evaluate(
    outside: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    args = ["evaluate", "--scenario", "Hopper-v5", "--out", "results", "--seeds", "3"]
    args += ["--checkpoint", f"mine={outside / 'model.zip'}:recurrent-ppo"]
    args += ["--normalizer", f"mine={outside / 'vecnormalize.pkl'}"]
    args += ["--adversaries", "nominal", "--budgets", "--workers", "1"]
    assert main(args) == 0
    got = {int(r["seed"]): float(r["true_return"]) for r in rows(tmp_path / "results")}
    want = plain_episodes(outside, [s * SEED_STRIDE for s in (0, 1, 2)])
    assert [got[0], got[1], got[2]] == want


def test_without_its_memory_the_policy_would_act_otherwise(outside: Path) -> None:
    game = advgame.make("Hopper-v5", disruptors={})
    policy = protagonist_of(outside, game)
    obs = gym.make("Hopper-v5").reset(seed=0)[0]
    policy.reset(0)
    first = policy.act(obs)
    second = policy.act(obs)  # same observation, one step of memory later
    assert not np.array_equal(first, second)
    policy.reset(0)  # the memory is zeroed at an episode start
    assert np.array_equal(policy.act(obs), first)
    h, c = policy.hidden_state()["actor"]
    assert h.shape == (1, 1, 16) and torch.any(h != 0) and torch.any(c != 0)


def test_white_box_methods_read_the_carried_state_without_advancing_it(outside: Path) -> None:
    game = advgame.make("Hopper-v5", disruptors={})
    policy = protagonist_of(outside, game)
    obs = gym.make("Hopper-v5").reset(seed=1)[0]
    policy.reset(0)
    x = torch.as_tensor(np.stack([obs, obs + 0.01]), dtype=torch.float32)
    fresh_mean, fresh_value = policy.action_mean(x), policy.value(x)
    for _ in range(3):
        policy.act(obs)
    before = policy.hidden_state()
    later_mean, later_value = policy.action_mean(x), policy.value(x)
    after = policy.hidden_state()
    for part in ("actor", "critic"):
        assert all(torch.equal(a, b) for a, b in zip(before[part], after[part], strict=True))
    assert not torch.allclose(fresh_mean, later_mean)
    assert not torch.allclose(fresh_value, later_value)
    # the deterministic action is the mean at the carried state, clipped to the action box
    step = policy.act(obs)
    np.testing.assert_allclose(
        step, later_mean[0].detach().numpy().clip(-1, 1), rtol=1e-5, atol=1e-6
    )
    # the critic's catch-up equals stepping the critic LSTM one observation at a time
    manual = (torch.zeros(1, 1, 16), torch.zeros(1, 1, 16))
    net = policy.model.policy
    with torch.no_grad():
        for _ in range(4):
            z = net.vf_features_extractor(
                policy._features(torch.as_tensor(obs[None], dtype=torch.float32))
            )
            _, manual = net.lstm_critic(z[:, None, :], manual)
    torch.testing.assert_close(policy.hidden_state()["critic"][0], manual[0])


def test_batched_play_keeps_one_memory_per_game(outside: Path) -> None:
    games = [advgame.make("Hopper-v5", disruptors={}) for _ in range(3)]
    spec = SB3Checkpoint(
        str(outside / "model.zip"), "recurrent-ppo", str(outside / "vecnormalize.pkl")
    )
    pols = [build_policies(g, {"protagonist": spec}) for g in games]
    together = rollout_batch(games, pols, [0, 1, 2])
    alone = [
        rollout(advgame.make("Hopper-v5", disruptors={}), {"protagonist": spec}, seed=s)[0]
        for s in (0, 1, 2)
    ]
    assert [r.true_return for r in together] == [r.true_return for r in alone]
    assert len({r.true_return for r in alone}) == 3
    one = pols[0]["protagonist"]
    with pytest.raises(ConfigError, match="one episode's memory"):
        one.act_batch(np.zeros((2, 11)))


def test_a_frozen_recurrent_protagonist_resets_its_memory_in_an_adversary_view(
    outside: Path,
) -> None:
    from advgame.core.views import SingleAgentView

    spec = SB3Checkpoint(
        str(outside / "model.zip"), "recurrent-ppo", str(outside / "vecnormalize.pkl")
    )
    game = advgame.make("Hopper-v5", preset="atla")
    view = SingleAgentView(game, "observation_adversary", {"protagonist": spec})
    victim = view.policies["protagonist"]
    assert isinstance(victim, RecurrentSB3Policy)
    view.reset(seed=0)
    noop = np.zeros(view.action_space.shape, dtype=np.float32)
    for _ in range(5):
        view.step(noop)  # two moves per step: the sense move, then the protagonist's act
    assert len(victim._seen) == 5  # one memory step per environment step, not per move
    view.reset(seed=1)
    assert victim._seen == [] and not torch.any(victim.hidden_state()["actor"][0])


@pytest.mark.parametrize("mixture", [False, True])
def test_training_views_ask_a_frozen_lstms_copies_in_one_pass(
    outside: Path, monkeypatch: pytest.MonkeyPatch, mixture: bool
) -> None:
    """Also behind a mixture (the optimal search's and PSRO's opponents), across a reset."""
    from advgame.core.vector import VectorView
    from advgame.core.views import view_factory
    from advgame.training.best_response import MixtureSpec

    spec: Any = SB3Checkpoint(
        str(outside / "model.zip"), "recurrent-ppo", str(outside / "vecnormalize.pkl")
    )
    if mixture:
        spec = MixtureSpec((spec,), (1.0,))
    fns = [
        view_factory("Hopper-v5", "observation_adversary", {"protagonist": spec}, preset="atla")
    ] * 3
    calls = {"group": 0, "act": 0}
    group, act = RecurrentSB3Policy.act_group, RecurrentSB3Policy.act

    def counted_group(self, policies, observations):  # type: ignore[no-untyped-def]
        calls["group"] += 1
        return group(self, policies, observations)

    def counted_act(self, observation):  # type: ignore[no-untyped-def]
        calls["act"] += 1
        return act(self, observation)

    monkeypatch.setattr(RecurrentSB3Policy, "act_group", counted_group)
    monkeypatch.setattr(RecurrentSB3Policy, "act", counted_act)
    memories = {}
    for exact in (True, False):
        venv = VectorView(fns, exact=exact)
        noop = np.zeros((3, *venv.action_space.shape), dtype=np.float32)
        venv.seed(0)
        venv.reset()
        for _ in range(5):  # then a new episode everywhere: every memory starts from zero
            venv.step(noop)
        venv.seed(0)
        venv.reset()
        calls.update(group=0, act=0)
        for _ in range(8):
            venv.step(noop)
        memories[exact] = [v.policies["protagonist"].hidden_state()["actor"] for v in venv.envs]
        steps = [len(v.policies["protagonist"]._seen) for v in venv.envs]
        assert steps == [8, 8, 8]  # one memory step per environment step, per copy
        assert calls == ({"group": 0, "act": 24} if exact else {"group": 8, "act": 0})
    for alone, together in zip(memories[True], memories[False], strict=True):
        # each copy's own row: the batched pass only rounds differently
        torch.testing.assert_close(together, alone, atol=1e-5, rtol=1e-5)
    assert not torch.equal(memories[True][0][0], memories[True][1][0])  # three different games


def test_a_released_lstm_adversary_loads_as_an_lstm(outside: Path, tmp_path: Path) -> None:
    from advgame.workflows import zoo

    entry = zoo.ZooEntry(
        id="hopper/atla-lstm", scenario="Hopper-v5", method="atla-lstm", steps=512, seed=0,
        natural_return=0.0, worst_attack_return=0.0, worst_attack="attack optimal",
        threat="atla", algo="recurrent-ppo",
    )  # fmt: skip
    model = outside / "model.zip"
    zoo.release(entry, {"protagonist": model, "adversary": model}, tmp_path)
    adversary = zoo.load(entry.id, tmp_path, adversary=True)
    assert adversary.algo == "recurrent-ppo"  # not refused as a PPO zip
    assert isinstance(build_policies(advgame.make("Hopper-v5"), {"protagonist": adversary})[
        "protagonist"], RecurrentSB3Policy)  # fmt: skip
    assert zoo.load(entry.id, tmp_path).algo == "recurrent-ppo"


def test_saved_recurrent_reads_the_kind_from_the_zip(outside: Path, tmp_path: Path) -> None:
    from stable_baselines3 import PPO

    plain = tmp_path / "plain.zip"
    PPO("MlpPolicy", "Pendulum-v1", n_steps=64, device="cpu").save(plain)
    damaged = tmp_path / "damaged.zip"
    damaged.write_bytes(b"not a zip")
    assert saved_recurrent(str(outside / "model.zip")) is True
    assert saved_recurrent(str(plain)) is False
    assert saved_recurrent(str(damaged)) is None  # the load itself reports the damage
    assert saved_recurrent(str(tmp_path / "missing.zip")) is None


def test_a_checkpoint_loaded_as_the_wrong_kind_is_refused_clearly(outside: Path) -> None:
    with pytest.raises(ConfigError, match="recurrent-ppo"):
        load_model(str(outside / "model.zip"), "ppo")
    game = advgame.make("Hopper-v5", disruptors={})
    info = AgentInfo(
        "protagonist", game.observation_space("protagonist"), game.action_space("protagonist")
    )
    with pytest.raises(ConfigError, match="RecurrentPPO"):
        RecurrentSB3Policy(object())
    assert isinstance(
        SB3Checkpoint(str(outside / "model.zip"), "recurrent-ppo").build(info), RecurrentSB3Policy
    )


def test_the_learner_config_is_registered_and_checked() -> None:
    assert LEARNERS["recurrent-ppo"] is RecurrentPPOConfig
    config = RecurrentPPOConfig()
    assert config.net_arch == () and config.lstm_hidden_size == 64
    with pytest.raises(ConfigError, match="lstm_hidden_size"):
        RecurrentPPOConfig(lstm_hidden_size=0)
    with pytest.raises(ConfigError, match="net_arch"):
        PPOConfig(net_arch=())  # only a recurrent policy may read its actions off the LSTM
    assert METHODS["atla-lstm"]["protagonist_algo"] == "recurrent-ppo"
    TrainConfig(protagonist_algo="recurrent-ppo", adversary_algo="recurrent-ppo")
    from gymnasium import spaces

    class DictEnv:
        observation_space = spaces.Dict({"a": spaces.Box(-1, 1, (2,))})

    with pytest.raises(ConfigError, match="flat"):
        config.make_model(DictEnv(), 0, 1)


def test_atla_lstm_trains_resumes_and_is_evaluated_from_the_cli(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "lstm"
    args = ["train", "--method", "atla-lstm", "--scenario", "Hopper-v5", "--run-dir", str(run)]
    assert main([*args, *TINY]) == 0
    population = json.loads((run / "population.json").read_text())
    algos = {m["spec"]["fields"].get("algo") for m in population if m["learned"]}
    assert algos == {"recurrent-ppo"}  # an LSTM adversary too
    config = json.loads((run / "config.json").read_text())
    assert config["protagonist_algo"] == "recurrent-ppo"
    first = load_model(str(run / "checkpoints" / "iter_0002" / "protagonist.zip"), "recurrent-ppo")
    (run / "config.json").write_text(json.dumps({**config, "iterations": 3}))
    assert main(["resume", str(run), "--no-progress"]) == 0
    second = load_model(str(run / "checkpoints" / "iter_0003" / "protagonist.zip"), "recurrent-ppo")
    assert second.num_timesteps == first.num_timesteps + 128  # it carried on from iteration 2
    assert second.policy.lstm_actor.weight_hh_l0.shape == (64, 16)
    out = tmp_path / "results"
    args = ["evaluate", str(run), "--adversaries", "nominal", "attack:random", "attack:mad"]
    assert main([*args, "attack:critic", "learned", "--seeds", "1", "--budgets", "--out", str(out),
                 "--workers", "1"]) == 0  # fmt: skip
    cells = {r["adversary"] for r in rows(out)}
    assert {"nominal", "attack random", "attack mad", "attack critic"} <= cells
    assert all(np.isfinite(float(r["true_return"])) for r in rows(out))


def test_psro_trains_and_plays_lstm_best_responses(tmp_path: Path) -> None:
    small = json.dumps({"n_steps": 64, "batch_size": 64, "lstm_hidden_size": 8})
    args = ["psro", "--run-dir", str(tmp_path / "psro"), "--scenario", "Hopper-v5"]
    args += ["--preset", "atla", "--iterations", "1", "--protagonist-steps", "64"]
    args += ["--adversary-steps", "64", "--protagonist-algo", "recurrent-ppo"]
    args += ["--adversary-algo", "recurrent-ppo", "--max-episode-steps", "50", "--eval-seeds", "1"]
    args += ["--set", f"protagonist_hparams={small}", "--set", f"adversary_hparams={small}"]
    assert main(args) == 0
    text = (tmp_path / "psro" / "population.json").read_text()
    assert '"algo": "recurrent-ppo"' in text and '"algo": "ppo"' not in text
