"""Multi-agent protagonists, part one: `TeamView` and SuperSuit/Stable-Baselines3 on it.

TeamView passes PettingZoo's parallel API and seed tests, its episodes are reproducible from the
seed, a team step is the act move then the sense move, protagonists see perturbed observations
and infos carry the true team payoff; then SuperSuit's agents-as-envs wrapping, plain SB3 PPO and
`SharedIPPO` on team views. Real MuJoCo (MaMuJoCo), real torch, real Stable-Baselines3 and
SuperSuit throughout.
"""

from __future__ import annotations

import pickle
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from pettingzoo.test import parallel_api_test, parallel_seed_test
from stable_baselines3 import PPO

import advgame
from advgame.adversaries import GaussianAdversary
from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.agents.common.stats import EpisodeStats
from advgame.agents.marl.shared import SharedIPPO
from advgame.agents.sb3.config import PPOConfig
from advgame.core.episodes import build_policies, filler_action, rollout
from advgame.core.policy import ConstantPolicy
from advgame.core.team import TeamView, team_factory
from advgame.disruptors import ObservationDisruptor
from advgame.errors import ActionError, ConfigError
from tests._marl_helpers import SID, _assert_same, noisy

ss = pytest.importorskip("supersuit", reason="the mamujoco extra: pip install '.[mamujoco]'")

PRESETS = ["default", "partial"]
SHORT = 25
"""Episode length of the conformance tests (MaMuJoCo's 1000 steps would only slow them)."""


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def team(preset: str, steps: int = SHORT) -> TeamView:
    game = advgame.make(SID, preset=preset, max_episode_steps=steps)
    return TeamView(game, noisy(game))


# -- TeamView: PettingZoo conformance and semantics ----------------------------------------------
@pytest.mark.parametrize("preset", PRESETS)
def test_team_view_passes_the_parallel_api_test(preset: str) -> None:
    view = team(preset)
    assert view.possible_agents == ["agent_0", "agent_1"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parallel_api_test(view, num_cycles=SHORT + 5)  # the episode ends inside the test
    view.close()


@pytest.mark.parametrize("preset", PRESETS)
def test_team_view_passes_the_parallel_seed_test(preset: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parallel_seed_test(lambda: team(preset), num_cycles=SHORT)


def _trace(view: TeamView, seed: int) -> list[Any]:
    """Everything a whole episode returns, for seeded random protagonist actions."""
    rng = np.random.default_rng(seed)
    out: list[Any] = [view.reset(seed=seed), view.state()]
    while view.agents:
        actions = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in view.agents}
        out += [view.step(actions), view.state()]
    return out


@pytest.mark.parametrize("preset", PRESETS)
def test_team_view_episodes_are_reproducible_from_the_seed(preset: str) -> None:
    # parallel_seed_test compares one step; this compares whole episodes, adversary noise included
    first, again, other = _trace(team(preset), 7), _trace(team(preset), 7), _trace(team(preset), 8)
    _assert_same(first, again)
    assert len(first) == 2 + 2 * SHORT
    assert not np.array_equal(first[0][0]["agent_0"], other[0][0]["agent_0"])


@pytest.mark.parametrize("preset", PRESETS)
def test_a_team_step_is_the_act_move_then_the_sense_move(preset: str) -> None:
    """Referee: the same game driven move by move through `Game.step` (the full PettingZoo form)."""
    view = team(preset)
    ref = advgame.make(SID, preset=preset, max_episode_steps=SHORT)
    zero = {p: ConstantPolicy(np.zeros(3, np.float32)) for p in ref.protagonists}
    pols = build_policies(ref, {**noisy(ref), **zero})
    seed, rng = 3, np.random.default_rng(0)
    obs, _ = view.reset(seed=seed)
    for s, a in zip(np.random.SeedSequence(seed).generate_state(2), ref.adversaries, strict=True):
        pols[a].reset(int(s))
    ref_obs, _ = ref.reset(seed=seed)

    def ref_move(protagonist_actions: dict[str, Any]) -> tuple:
        # every agent sends an action; only those of `next_movers` count (and draw noise)
        actions = {
            a: pols[a].act(ref_obs[a])
            if a in ref.next_movers
            else filler_action(ref.action_space(a))
            for a in ref.adversaries
        }
        return ref.step({**actions, **protagonist_actions})

    if ref.move == "sense":
        ref_obs = ref_move({p: np.zeros(3, np.float32) for p in ref.protagonists})[0]
    while view.agents:
        for p in view.agents:
            np.testing.assert_array_equal(obs[p], ref_obs[p])
        np.testing.assert_array_equal(view.state(), ref.state())
        acts = {p: rng.uniform(-1, 1, 3).astype(np.float32) for p in view.agents}
        obs, rewards, terms, truncs, infos = view.step(acts)
        assert ref.move == "act"
        ref_obs, ref_rew, ref_terms, ref_truncs, ref_infos = ref_move(acts)
        for p in ref.protagonists:
            assert rewards[p] == ref_rew[p]
            assert infos[p]["true_reward"] == ref_infos[p]["true_reward"]
            assert infos[p]["payoff"] == -ref_rew["action_adversary"]
            assert (terms[p], truncs[p]) == (ref_terms[p], ref_truncs[p])
        if ref.agents and ref.move == "sense":
            ref_obs = ref_move({p: np.zeros(3, np.float32) for p in ref.protagonists})[0]
    assert not ref.agents and truncs == {"agent_0": True, "agent_1": True}


def test_protagonists_see_perturbed_observations_but_state_is_the_true_one() -> None:
    attacked = advgame.make(SID, disruptors={"observation": {"eps": 0.1}}, max_episode_steps=SHORT)
    view = TeamView(attacked, noisy(attacked, std=0.1))
    nominal = TeamView(advgame.make(SID, disruptors=[], max_episode_steps=SHORT))
    obs, _ = view.reset(seed=1)
    clean, _ = nominal.reset(seed=1)
    for _ in range(5):
        np.testing.assert_array_equal(view.state(), nominal.state())
        for a in view.agents:
            delta = obs[a] - clean[a]
            assert 0 < np.abs(delta).max() <= 0.1 + 1e-9  # perturbed, inside the budget
        acts = {a: np.full(3, 0.3, np.float32) for a in view.agents}
        obs, rewards, *_ = view.step(acts)
        clean, clean_rewards, *_ = nominal.step(acts)
        assert rewards == clean_rewards  # the observation attack changed nothing else yet


def test_rewards_are_observed_per_agent_and_infos_carry_the_true_team_payoff() -> None:
    game = advgame.make(
        SID, disruptors={"reward": {"eps": 0.5, "targets": ["agent_0"]}}, max_episode_steps=SHORT
    )
    view = TeamView(game, noisy(game, std=0.5))
    view.reset(seed=0)
    _, rewards, _, _, infos = view.step({a: np.full(3, 0.5, np.float32) for a in view.agents})
    assert infos["agent_0"] is not infos["agent_1"]
    for key in ("true_reward", "true_cost", "payoff", "cost"):
        assert key in infos["agent_0"] and key in infos["agent_1"]
    true = infos["agent_0"]["true_reward"]
    assert infos["agent_1"]["true_reward"] == true == infos["agent_0"]["payoff"]
    assert rewards["agent_1"] == true  # not targeted
    assert rewards["agent_0"] != true and abs(rewards["agent_0"] - true) <= 0.5 + 1e-9


def test_team_view_errors_say_what_to_fix() -> None:
    game = advgame.make(SID, max_episode_steps=2)
    with pytest.raises(ConfigError, match="protagonists"):
        TeamView(game, {"agent_0": ConstantPolicy(np.zeros(3))})
    view = TeamView(game)
    with pytest.raises(ConfigError, match="adversary"):
        view.observation_space("observation_adversary")
    with pytest.raises(ConfigError, match="unknown agents"):
        view.set_policies({"observation_adversry": GaussianAdversary()})
    view.reset(seed=0)
    with pytest.raises(ActionError, match="agent_1"):
        view.step({"agent_0": np.zeros(3, np.float32)})
    for _ in range(2):
        view.step({a: np.zeros(3, np.float32) for a in view.agents})
    assert view.agents == []
    with pytest.raises(ActionError, match="reset"):
        view.step({a: np.zeros(3, np.float32) for a in view.possible_agents})


def test_team_factory_pickles_and_set_policies_swaps_only_the_named_adversary() -> None:
    fn = pickle.loads(pickle.dumps(team_factory(SID, {"action_adversary": GaussianAdversary()})))
    view = fn()
    before = view.policies["observation_adversary"]
    assert isinstance(before, ConstantPolicy)  # missing adversaries play their no-op
    view.set_policies({"observation_adversary": GaussianAdversary(std=0.2)})
    assert view.policies["observation_adversary"] is not before
    assert not isinstance(view.policies["observation_adversary"], ConstantPolicy)
    assert not isinstance(view.policies["action_adversary"], ConstantPolicy)


def test_set_observation_scale_reaches_normalized_budgets() -> None:
    game = advgame.make(SID, disruptors=[ObservationDisruptor(eps=0.1, space="normalized")])
    view = TeamView(game)
    std = np.linspace(0.5, 2.0, 12)
    assert view.set_observation_scale("agent_1", std) == 1
    np.testing.assert_array_equal(game.disruptors["observation_adversary"].scale["agent_1"], std)
    assert TeamView(advgame.make(SID)).set_observation_scale("agent_1", std) == 0  # raw budgets


# -- SuperSuit and Stable-Baselines3 ---------------------------------------------------------------
def _supersuit_venv(n: int) -> Any:
    padded = ss.pad_action_space_v0(ss.pad_observations_v0(team("default")))
    vec = ss.pettingzoo_env_to_vec_env_v1(padded)
    return ss.concat_vec_envs_v1(vec, n, num_cpus=0, base_class="stable_baselines3")


def test_team_view_steps_under_supersuit_agents_as_envs() -> None:
    venv = _supersuit_venv(2)
    assert venv.num_envs == 4  # 2 views x 2 protagonists
    obs = venv.reset()
    assert obs.shape == (4, 12)
    for t in range(SHORT):
        obs, rewards, dones, infos = venv.step(np.zeros((4, 3), np.float32))
        assert all("true_reward" in info for info in infos)
        assert rewards[0] == rewards[1] == np.float32(infos[0]["true_reward"])  # one team reward
        assert dones.all() == (t == SHORT - 1)
    assert all(info["terminal_observation"].shape == (12,) for info in infos)
    venv.close()


def test_sb3_ppo_trains_on_supersuit_wrapped_team_views() -> None:
    venv = _supersuit_venv(2)
    # no seed=...: SuperSuit's SB3 adapter has no seed() (SB3 >= 2 calls it); SharedIPPO adds it
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=64, n_epochs=2, device="cpu")
    before = {k: v.clone() for k, v in model.policy.state_dict().items()}
    model.learn(total_timesteps=300)
    assert model.num_timesteps >= 300
    after = model.policy.state_dict()
    assert all(torch.isfinite(v).all() for v in after.values())
    assert "log_std" in {k for k in before if not torch.equal(before[k], after[k])}
    venv.close()


def test_shared_ippo_learns_saves_and_plays_in_rollout(tmp_path: Path) -> None:
    fn = team_factory(SID, preset="default", max_episode_steps=50)
    learner = SharedIPPO(
        PPOConfig(n_steps=100, batch_size=50), fn, seed=0, total_steps=400, n_envs=2
    )
    learner.set_policies({"observation_adversary": GaussianAdversary(std=0.05)})
    assert all(
        not isinstance(v.policies["observation_adversary"], ConstantPolicy)
        for v in learner._views()
    )
    stats = EpisodeStats()
    learner.learn(200, stats)
    assert learner.steps == 200 and learner.model.num_timesteps == 400
    assert (
        len(stats.true_returns) == 4
    )  # 2 teams x 100 steps = 2 episodes each, one return per team
    std = learner.observation_std()
    assert std is not None and set(std) == {"agent_0", "agent_1"}
    specs = learner.save(tmp_path)
    assert specs["agent_0"] == specs["agent_1"] and isinstance(specs["agent_0"], SB3Checkpoint)
    game = advgame.make(SID, preset="default", max_episode_steps=50)
    results = rollout(game, {**specs, **noisy(game)}, seed=0, episodes=2)
    assert [r.length for r in results] == [50, 50]
    resumed = SharedIPPO.load(tmp_path, PPOConfig(n_steps=100, batch_size=50), fn, n_envs=2)
    assert resumed.steps == 200
    for v in (learner, resumed):
        v.close()


def test_shared_ippo_refuses_a_heterogeneous_team() -> None:
    with pytest.raises(ConfigError, match="same observation and action shapes"):
        SharedIPPO(PPOConfig(), team_factory("MA-Hopper-3x1"), seed=0, total_steps=10)
