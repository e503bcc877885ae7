"""OMPO is OMPO: its losses against hand computations, its discriminator, its update schedule.

Every check here can fail: the losses are recomputed from the formulas of the authors' code
(``Roythuly/OMPO``: ``model/algo.py``) with the networks' own layers but none of
`advgame.agents.ompo.ompo`'s code; the discriminator must separate two transition models it was
trained on and not two samples of one; the schedule is counted.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.type_aliases import ReplayBufferSamples
from stable_baselines3.common.vec_env import DummyVecEnv

from advgame.agents.ompo.config import OMPOConfig
from advgame.agents.ompo.ompo import OMPO, OMPOReplayBuffer, TransitionDiscriminator
from advgame.errors import ConfigError

GAMMA, TOMAC, P, MIX = 0.99, 1e-3, 1.5, 0.05
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _model(**kwargs) -> OMPO:
    env = DummyVecEnv([lambda: gym.make("InvertedPendulum-v5")])
    options = {"learning_starts": 50, "batch_size": 16, "local_size": 40, "disc_batch": 8}
    options.update(kwargs)
    cfg = OMPOConfig(net_arch=(16, 16), **options)
    return cfg.make_model(env, seed=0, total_steps=1000)


def _batch(n: int = 12, seed: int = 0) -> tuple[ReplayBufferSamples, th.Tensor]:
    g = th.Generator().manual_seed(seed)
    obs, nxt = th.randn(n, 4, generator=g), th.randn(n, 4, generator=g)
    act = th.rand(n, 1, generator=g) * 2 - 1
    rew = th.randn(n, 1, generator=g) * 2  # some below -1: the clamp at 1e-6 is exercised
    rew[0] = -5.0
    done = (th.rand(n, 1, generator=g) < 0.3).float()
    return ReplayBufferSamples(obs, act, nxt, done, rew), th.randn(n, 4, generator=g)


def _fixed_policy(model: OMPO) -> None:
    """A deterministic, differentiable stand-in for the actor's sampling (same in both sides)."""
    actor = model.actor

    def action_log_prob(obs: th.Tensor):
        mean, log_std, _ = actor.get_action_dist_params(obs)
        action = th.tanh(mean + 0.3 * th.exp(log_std))
        return action, (log_std.sum(dim=1) - action.pow(2).sum(dim=1))

    actor.action_log_prob = action_log_prob  # type: ignore[method-assign]


def _q(net: th.nn.Module, obs: th.Tensor, act: th.Tensor) -> th.Tensor:
    return net(th.cat([obs, act], dim=1))


def _hand_targets(model: OMPO, data, alpha: float) -> list[th.Tensor]:
    logit = model.discriminator.trunk(
        th.cat([data.observations, data.actions, data.next_observations], 1)
    )
    reward = th.clamp(data.rewards + 1.0, min=1e-6) - TOMAC * logit
    a2, logp2 = model.actor.action_log_prob(data.next_observations)
    online = [_q(net, data.next_observations, a2) for net in model.critic.q_networks]
    targ = [_q(net, data.next_observations, a2) for net in model.critic_target.q_networks]
    low = th.minimum(targ[0], targ[1])
    return [
        reward
        + GAMMA * (1 - data.dones) * (MIX * q + (1 - MIX) * low - alpha * logp2.reshape(-1, 1))
        for q in online
    ]


def test_critic_loss_is_the_formula() -> None:
    model = _model()
    _fixed_policy(model)
    data, init = _batch()
    alpha = th.tensor(0.37)
    got = model.critic_loss(data, init, alpha)
    with th.no_grad():
        ys = _hand_targets(model, data, 0.37)
        a0, _ = model.actor.action_log_prob(init)
        want = 0.0
        for k, net in enumerate(model.critic.q_networks):
            resid = ys[k] - _q(net, data.observations, data.actions)
            q0 = _q(net, init, a0)
            want += (resid.abs().pow(P) / P + (1 - GAMMA) * TOMAC * q0).mean()
    assert float(got.detach()) == pytest.approx(float(want.detach()), rel=1e-5)
    # the clamp matters: without it the first (r = -5) row's reward would be -4
    assert float(model.shaped_reward(data)[0]) == pytest.approx(
        1e-6
        - TOMAC
        * float(
            model.discriminator.logit(
                th.cat([data.observations, data.actions, data.next_observations], 1)
            )[0]
        ),
        abs=1e-7,
    )


def test_actor_loss_and_its_gradient_are_the_formula() -> None:
    model = _model()
    _fixed_policy(model)
    data, init = _batch(seed=1)
    alpha = th.tensor(0.2)
    params = list(model.actor.parameters())
    got = model.actor_loss(data, init, alpha)
    got_grad = th.autograd.grad(got, params)
    ys = _hand_targets(model, data, 0.2)
    a0, _ = model.actor.action_log_prob(init)
    terms = []
    for k, net in enumerate(model.critic.q_networks):
        resid = ys[k] - _q(net, data.observations, data.actions).detach()
        weight = th.clamp(resid, 0, 1e6).pow(P - 1).detach()
        terms.append(-(weight * resid + (1 - GAMMA) * TOMAC * _q(net, init, a0)).mean())
    want = (terms[0] + terms[1]) / 2
    want_grad = th.autograd.grad(want, params)
    assert float(got.detach()) == pytest.approx(float(want.detach()), rel=1e-5)
    for a, b in zip(got_grad, want_grad, strict=True):
        assert th.allclose(a, b, rtol=1e-4, atol=1e-7)
    assert any(float(g.abs().sum()) > 0 for g in got_grad)  # the policy does get a gradient


def _transitions(n: int, shift: float, rng: np.random.Generator) -> th.Tensor:
    s = rng.normal(size=(n, 3))
    a = rng.uniform(-1, 1, size=(n, 1))
    nxt = 0.9 * s + 0.5 * a + shift + 0.05 * rng.normal(size=(n, 3))
    return th.as_tensor(np.concatenate([s, a, nxt], 1), dtype=th.float32)


def _trained(
    local_shift: float, other_shift: float, seed: int = 0
) -> tuple[TransitionDiscriminator, np.random.Generator]:
    th.manual_seed(seed)
    rng = np.random.default_rng(seed)
    disc = TransitionDiscriminator(7, hidden=64)
    local, other = _transitions(1000, local_shift, rng), _transitions(1000, other_shift, rng)
    for _ in range(300):
        i, j = rng.integers(0, 1000, 128), rng.integers(0, 1000, 128)
        disc.update(local[i], other[j])
    return disc, rng


def test_discriminator_separates_two_dynamics_with_the_right_sign() -> None:
    disc, rng = _trained(local_shift=1.0, other_shift=-1.0)
    local, other = _transitions(500, 1.0, rng), _transitions(500, -1.0, rng)  # held out
    lo, ot = disc.logit(local).numpy().ravel(), disc.logit(other).numpy().ravel()
    accuracy = ((lo > 0).mean() + (ot < 0).mean()) / 2
    assert accuracy > 0.9
    assert lo.mean() > 0 > ot.mean()  # logit = log rho_local / rho_global


def test_correction_vanishes_when_local_and_global_dynamics_agree() -> None:
    same, rng = _trained(local_shift=1.0, other_shift=1.0)
    apart, _ = _trained(local_shift=1.0, other_shift=-1.0)
    held = _transitions(500, 1.0, rng)
    assert float(same.logit(held).abs().mean()) < 0.35
    assert float(same.logit(held).abs().mean()) < 0.25 * float(apart.logit(held).abs().mean())


def test_update_schedule_is_counted() -> None:
    model = _model(learning_starts=50, local_size=40)
    model.learn(200)
    updates = 3 * (200 - 50)  # SB3 trains after each step once num_timesteps > learning_starts
    assert model.counts["critic"] == updates
    assert model.counts["actor"] == model.counts["target"] == (updates + 1) // 2
    # the discriminator trains (10 rounds x 20 updates) whenever 40 new transitions have come
    trainings = model.counts["discriminator"] // 200
    assert model.counts["discriminator"] == 200 * trainings and trainings == (200 - 50) // 40 + 1
    assert model.since_discriminator < 40


def test_initial_states_are_the_episodes_first_observations() -> None:
    env = DummyVecEnv([lambda: gym.make("InvertedPendulum-v5")])
    buf = OMPOReplayBuffer(100, env.observation_space, env.action_space, n_envs=1)
    obs = np.zeros((1, 4), np.float32)
    for t, done in enumerate([False, False, True, False, True, False]):
        buf.add(obs + t, obs + t + 1, np.zeros((1, 1)), np.zeros(1), np.array([done]), [{}])
    assert [float(x[0]) for x in buf.initial] == [0.0, 3.0, 5.0]
    assert ReplayBuffer in type(buf).__mro__


def test_save_load_keeps_the_discriminator_and_the_counts(tmp_path) -> None:
    model = _model(learning_starts=30, local_size=20)
    model.learn(80)
    model.save(tmp_path / "m.zip")
    model.save_replay_buffer(tmp_path / "r.pkl")
    back = OMPO.load(tmp_path / "m.zip", device="cpu")
    back.load_replay_buffer(tmp_path / "r.pkl")
    x = th.randn(5, 9)
    assert th.equal(back.discriminator.logit(x), model.discriminator.logit(x))
    assert back.counts == model.counts and back.since_discriminator == model.since_discriminator
    assert len(back.replay_buffer.initial) == len(model.replay_buffer.initial) > 0
    # a resumed run starts fresh episodes: its first state is an s₀ (mid-episode when saved)
    model.replay_buffer._starts[:] = False
    model.save_replay_buffer(tmp_path / "r.pkl")
    back.load_replay_buffer(tmp_path / "r.pkl")
    buf = back.replay_buffer
    before = len(buf.initial)
    obs = np.full((buf.n_envs, *buf.obs_shape), 7.0, dtype=np.float32)
    act = np.zeros((buf.n_envs, buf.action_dim), dtype=np.float32)
    buf.add(obs, obs, act, np.zeros(buf.n_envs), np.zeros(buf.n_envs), [{}] * buf.n_envs)
    assert len(buf.initial) == before + buf.n_envs and float(buf.initial[-1][0]) == 7.0


def test_refuses_discrete_actions_before_training() -> None:
    env = DummyVecEnv([lambda: gym.make("CartPole-v1")])
    with pytest.raises(ConfigError, match="continuous"):
        OMPOConfig().make_model(env, seed=0, total_steps=10)


@pytest.mark.slow
def test_ompo_learns_to_balance_the_inverted_pendulum() -> None:
    """OMPO with the paper's table learns a real task: 1,000 random then 6,000 learning steps."""
    env = DummyVecEnv([lambda: gym.make("InvertedPendulum-v5")])
    model = OMPOConfig(learning_starts=1000).make_model(env, seed=0, total_steps=7000)
    model.learn(7000)
    ev = gym.make("InvertedPendulum-v5")
    returns = []
    for ep in range(3):
        obs, _ = ev.reset(seed=100 + ep)
        done, total = False, 0.0
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, term, trunc, _ = ev.step(action)
            total, done = total + float(reward), term or trunc
        returns.append(total)
    assert np.mean(returns) > 900  # the maximum is 1,000; a random policy keeps it up ~5 steps


def test_sigmoid_tanh_is_tanh_in_value_gradient_and_second_gradient() -> None:
    from advgame.agents.ompo.nets import OMPOPolicy, SigmoidTanh

    x = th.linspace(-12, 12, 2001, dtype=th.float64).reshape(-1, 1).requires_grad_(True)
    fast = SigmoidTanh()
    assert th.allclose(fast(x), th.tanh(x), atol=1e-15, rtol=0)
    (g_fast,) = th.autograd.grad(fast(x).sum(), x)
    (g_ref,) = th.autograd.grad(th.tanh(x).sum(), x)
    assert th.allclose(g_fast, g_ref, atol=1e-12)
    # the discriminator's gradient penalty differentiates the gradient
    assert th.autograd.gradgradcheck(fast, (x[::100].detach().requires_grad_(True),))
    x32 = th.randn(512, 256)
    assert (fast(x32) - th.tanh(x32)).abs().max() < 5e-7
    model = OMPO("MlpPolicy", "Pendulum-v1", device="cpu", seed=0)
    assert isinstance(model.policy, OMPOPolicy)
    assert model.critic.optimizer.defaults["fused"] and model.actor.optimizer.defaults["fused"]
    assert any(isinstance(m, SigmoidTanh) for m in model.critic.modules())
