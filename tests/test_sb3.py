"""Short, real Stable-Baselines3 PPO training on both sides of a game through `SingleAgentView`."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

import advgame
from advgame import adversaries as adv
from advgame.core.views import SingleAgentView

TIMESTEPS = 2048


def fixed_hopper_protagonist(obs: np.ndarray) -> np.ndarray:
    """A frozen protagonist: a plain callable observation -> action."""
    return np.clip(-0.5 * np.asarray(obs[5:8], dtype=np.float64), -1.0, 1.0).astype(np.float32)


def protagonist_view() -> SingleAgentView:
    game = advgame.make("Hopper-v5", preset="default")
    return SingleAgentView(
        game,
        "protagonist",
        {
            "observation_adversary": adv.GaussianAdversary(std=0.05),
            "action_adversary": adv.GaussianAdversary(std=0.05),
        },
    )


def observation_adversary_view() -> SingleAgentView:
    game = advgame.make("Hopper-v5", preset="default")
    return SingleAgentView(game, "observation_adversary", {"protagonist": fixed_hopper_protagonist})


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _snapshot(model: PPO) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in model.policy.state_dict().items()}


@pytest.mark.parametrize(
    "make_view",
    [protagonist_view, observation_adversary_view],
    ids=["protagonist", "observation-adversary"],
)
def test_ppo_trains_on_the_view(make_view) -> None:
    view = make_view()
    model = PPO(
        "MlpPolicy",
        view,
        n_steps=512,
        batch_size=128,
        n_epochs=2,
        learning_rate=1e-3,
        policy_kwargs={"net_arch": [32, 32]},
        seed=0,
        device="cpu",
        verbose=0,
    )
    before = _snapshot(model)
    model.learn(total_timesteps=TIMESTEPS)
    assert model.num_timesteps >= TIMESTEPS
    after = _snapshot(model)
    assert before.keys() == after.keys()
    assert all(torch.isfinite(v).all() for v in after.values())
    changed = {k for k in before if not torch.equal(before[k], after[k])}
    # the actor (hidden layers, mean head, log-std) and the critic all learned
    assert "log_std" in changed
    assert any(k.startswith("mlp_extractor.policy_net") for k in changed)
    assert any(k.startswith("action_net") for k in changed)
    assert any(k.startswith("value_net") for k in changed)

    # the trained policy acts inside the view's action space, and the game accepts its actions
    obs, _ = view.reset(seed=1)
    actions = []
    for i in range(50):
        action, _ = model.predict(obs, deterministic=i % 2 == 0)
        assert view.action_space.contains(action), action
        actions.append(action)
        obs, reward, terminated, truncated, _ = view.step(action)
        assert np.isfinite(reward)
        if terminated or truncated:
            obs, _ = view.reset()
    assert np.ptp(np.stack(actions), axis=0).max() > 0.0  # the policy reacts to its input
    view.close()


@pytest.mark.parametrize("algo", ["ppo", "recurrent-ppo"])
def test_an_update_changes_the_weights_stamp_numpy_copies_check(algo: str) -> None:
    """NumPy copies of a live learner (PGD-AT, SA-PPO, a frozen LSTM's group step) are rebuilt
    when `weights_stamp` changes: the optimizer must mark what it updates (PyTorch's fused Adam
    does not bump ``_version``; the foreach kernel does)."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    from advgame.agents import PPOConfig, RecurrentPPOConfig
    from advgame.core.numpy_net import weights_stamp

    cls = PPOConfig if algo == "ppo" else RecurrentPPOConfig
    model = cls(n_steps=64, batch_size=32, n_epochs=1).make_model(
        DummyVecEnv([lambda: gym.make("Pendulum-v1")]), seed=0, total_steps=128
    )
    before = weights_stamp([model.policy])
    model.learn(64)
    assert weights_stamp([model.policy]) != before
