"""A recurrent victim's heads as a `NumpyNet` with one LSTM step at the memory it carries now.

What white-box attacks walk for an sb3-contrib ``RecurrentPPO`` victim: the same function and
input gradient as torch's `action_mean` and `value` at the carried memory (the critic's own,
caught up; the actor's for a shared LSTM), lone rows in batches, a new memory at every call on
the weights copied once, None where not covered, and attacks walking in NumPy to what their
torch walk reaches.
"""

from __future__ import annotations

import copy
import functools
import warnings
from typing import Any

import numpy as np
import pytest
import torch
from torch import nn

import advgame
from advgame.adversaries.whitebox import CriticAttack, MADAttack
from advgame.adversaries.whitebox_walk import WhiteBoxAttackPolicy
from advgame.agents.common.recurrent_policy import RecurrentSB3Policy
from advgame.core.episodes import build_policies
from advgame.core.numpy_lstm import _sigmoid
from advgame.core.numpy_net import NumpyNet
from advgame.disruptors import ObservationDisruptor

pytestmark = pytest.mark.usefixtures("one_torch_thread")
ADV = "observation_adversary"
ENV = "Hopper-v5"
CONFIGS: dict[str, dict[str, Any]] = {
    "critic-lstm": {},  # sb3-contrib's default: the critic has its own LSTM and memory
    "shared": {"shared_lstm": True, "enable_critic_lstm": False},
    "no-critic-lstm": {"enable_critic_lstm": False},  # the critic: a linear layer, no memory
    "mlp": {"net_arch": [16, 16]},  # tanh layers between the LSTM and the heads
}


@functools.cache
def _model(config: str, **extra: Any) -> Any:
    import gymnasium as gym
    from sb3_contrib import RecurrentPPO

    kwargs = {"lstm_hidden_size": 8, "net_arch": [], **CONFIGS.get(config, {}), **extra}
    model = RecurrentPPO("MlpLstmPolicy", gym.make(ENV), policy_kwargs=kwargs, seed=0)
    policy: Any = model.policy
    with torch.no_grad():  # non-zero biases, so that every gate term is exercised
        for name, p in policy.named_parameters():
            if "bias" in name:
                p.copy_(torch.randn(p.shape, generator=torch.Generator().manual_seed(1)) * 0.3)
        policy.action_net.weight.mul_(30.0)  # not SB3's near-zero initial mean
    return model


def _victim(config: str, steps: int = 3) -> RecurrentSB3Policy:
    """The victim behind a tight normalizer (some inputs clipped), after `steps` actions."""
    rng = np.random.default_rng(0)
    victim = RecurrentSB3Policy(
        _model(config), rng.normal(size=11), rng.uniform(0.5, 2.0, 11), clip_obs=2.0
    )
    victim.reset(0)
    for _ in range(steps):
        victim.act(rng.normal(size=11) * 3)
    return victim


def _torch_head(victim: RecurrentSB3Policy, head: str, obs: torch.Tensor) -> torch.Tensor:
    """Torch's head at the carried memory; a shared LSTM's value without sb3-contrib's detach."""
    policy = victim.model.policy
    if head == "mean":
        return victim.action_mean(obs)
    if not policy.shared_lstm:
        return victim.value(obs)[:, None]
    mean, std = (torch.as_tensor(v, dtype=torch.float32) for v in (victim.mean, victim.std))
    x = ((obs - mean) / std).clamp(-victim.clip_obs, victim.clip_obs)
    h, c = victim.hidden_state()["actor"]
    n = len(x)
    latent, _ = policy.lstm_actor(x[None], (h.expand(-1, n, -1), c.expand(-1, n, -1)))
    return policy.value_net(policy.mlp_extractor.forward_critic(latent[0]))


@pytest.mark.parametrize("config", list(CONFIGS))
@pytest.mark.parametrize("head", ["mean", "value"])
def test_the_numpy_net_is_the_heads_function_and_gradient_at_the_memory(
    config: str, head: str
) -> None:
    victim = _victim(config)
    assert victim.hidden_state()["actor"][0].abs().min() > 0  # a memory that is not the zero one
    net = victim.numpy_net(head)
    assert net is not None
    rng = np.random.default_rng(1)
    obs = (rng.normal(size=(9, 11)) * 3).astype(np.float32)
    out, tape = net.forward(obs)
    weights = rng.normal(size=out.shape).astype(np.float32)
    x = torch.as_tensor(obs).requires_grad_(True)
    expected = _torch_head(victim, head, x)
    (expected_grad,) = torch.autograd.grad((expected * torch.as_tensor(weights)).sum(), x)
    np.testing.assert_allclose(out, expected.detach().numpy(), rtol=1e-5, atol=1e-6)
    grad = net.backward(tape, weights)
    np.testing.assert_allclose(grad, expected_grad.numpy(), rtol=1e-4, atol=1e-6)
    assert (grad == 0).any() and (grad != 0).any()  # clipped inputs pass no gradient, others do
    assert out.dtype == grad.dtype == np.float32


def test_saturated_gates_are_torchs_exact_zeros_and_ones() -> None:
    z = np.concatenate([np.linspace(-120, 120, 4001), [-1e4, 1e4]]).astype(np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow warning where exp(-z) is infinite
        ours = _sigmoid(z)
    theirs = torch.sigmoid(torch.as_tensor(z)).numpy()
    np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=0)
    assert np.array_equal(ours == 0, theirs == 0) and np.array_equal(ours == 1, theirs == 1)


@pytest.mark.parametrize("head", ["mean", "value"])
def test_batched_rows_are_lone_rows(head: str) -> None:
    net = _victim("mlp").numpy_net(head)
    assert net is not None
    obs = (np.random.default_rng(2).normal(size=(17, 11)) * 3).astype(np.float32)
    out, tape = net.forward(obs)
    grad = net.backward(tape, np.ones_like(out))
    for i in range(len(obs)):
        lone, lone_tape = net.forward(obs[i : i + 1])
        assert np.array_equal(lone[0], out[i])
        assert np.array_equal(net.backward(lone_tape, np.ones_like(lone))[0], grad[i])


def _net(victim: RecurrentSB3Policy, head: str) -> NumpyNet:
    net = victim.numpy_net(head)
    assert net is not None
    return net


def _agrees(victim: RecurrentSB3Policy, head: str, obs: np.ndarray) -> np.ndarray:
    """The head's NumPy output, checked equal to torch's at the memory carried now."""
    out = _net(victim, head).forward(obs)[0]
    with torch.no_grad():
        expected = _torch_head(victim, head, torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(out, expected, rtol=1e-5, atol=1e-6)
    return out


def test_each_call_reads_the_memory_now_on_weights_copied_once() -> None:
    victim = _victim("critic-lstm", steps=0)
    obs = np.random.default_rng(3).normal(size=(4, 11)).astype(np.float32)
    first, cell = _agrees(victim, "mean", obs), _net(victim, "mean")._layers[0][1]
    values = _agrees(victim, "value", obs)
    victim.act(obs[0])
    assert not np.array_equal(_agrees(victim, "mean", obs), first)  # the actor's memory moved
    assert not np.array_equal(_agrees(victim, "value", obs), values)  # the critic caught up
    again = _net(victim, "mean")._layers[0][1]
    assert again._w is cell._w and again._w_hh_t is cell._w_hh_t  # the weights: not copied again
    victim.reset(1)  # a new episode: the zero memory again
    np.testing.assert_array_equal(_agrees(victim, "mean", obs), first)
    lstm = victim.model.policy.lstm_actor
    saved = lstm.weight_ih_l0.detach().clone()
    try:
        with torch.no_grad():
            lstm.weight_ih_l0.add_(0.5)  # an update in place: the copy is rebuilt
        assert not np.array_equal(_agrees(victim, "mean", obs), first)
    finally:
        with torch.no_grad():
            lstm.weight_ih_l0.copy_(saved)


def test_what_the_numpy_lstm_does_not_cover_stays_in_torch() -> None:
    import gymnasium as gym
    from sb3_contrib import RecurrentPPO

    two = RecurrentSB3Policy(_model("two-layers", n_lstm_layers=2))
    assert two.numpy_net("mean") is None and two.numpy_net("value") is None
    discrete = RecurrentPPO("MlpLstmPolicy", gym.make("CartPole-v1"), seed=0)
    assert RecurrentSB3Policy(discrete).numpy_net("mean") is None  # not a Gaussian
    assert RecurrentSB3Policy(discrete).numpy_net("value") is not None
    assert NumpyNet.of([nn.LSTM(3, 4, bidirectional=True), nn.Linear(8, 1)]) is None
    assert NumpyNet.of([nn.Linear(3, 3), nn.LSTM(3, 4)]) is None  # an LSTM step only first
    linear = NumpyNet.of([nn.Linear(3, 2)])
    assert linear is not None
    with pytest.raises(ValueError, match="starts with an LSTM"):
        linear.at_memory(np.zeros(2), np.zeros(2))


WALKS = [("mad", "critic-lstm"), ("mad", "mlp"), ("critic", "critic-lstm"),
         ("critic", "no-critic-lstm")]  # fmt: skip


@pytest.mark.parametrize(("attack", "config"), WALKS)
def test_attacks_walk_in_numpy_to_what_the_torch_walk_reaches(
    attack: str, config: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    victim = _victim(config, steps=0)
    spec = MADAttack(steps=10) if attack == "mad" else CriticAttack(steps=10)
    game = advgame.make(ENV, disruptors=[ObservationDisruptor(eps=0.3)])
    policy: WhiteBoxAttackPolicy = build_policies(game, {"protagonist": victim, ADV: spec})[ADV]
    policy.reset(0)
    game.reset(seed=3)
    rng = np.random.default_rng(4)
    for _ in range(4):  # along an episode: the memory moves between attacked steps
        torch_walk = policy._torch_walk([policy], "protagonist")
        walk = policy._walk([policy], "protagonist")
        for u in rng.uniform(-1, 1, size=(3, 1, 11)):
            scores, grad = walk(u)
            expected_scores, expected_grad = torch_walk(u)
            np.testing.assert_allclose(scores, expected_scores, rtol=1e-5, atol=1e-7)
            np.testing.assert_allclose(grad(), expected_grad(), rtol=1e-4, atol=1e-7)
        starts = copy.deepcopy(policy.rng)
        with monkeypatch.context() as patch:
            patch.setattr(WhiteBoxAttackPolicy, "_torch_walk", _refuse)
            u_numpy = policy.act(game.observe(ADV))
        policy.rng = starts
        with monkeypatch.context() as patch:  # the same starts, through torch
            patch.setattr(victim, "numpy_net", lambda head: None)
            u_torch = policy.act(game.observe(ADV))
        assert np.mean(np.abs(u_numpy - u_torch) < 1e-5) >= 0.9  # (here: all equal)
        reached = policy.objective_of("protagonist", u_numpy)
        expected = policy.objective_of("protagonist", u_torch)
        assert reached >= expected - 1e-5 * abs(expected) - 1e-9
        game.play({ADV: u_numpy})
        game.play({"protagonist": victim.act(game.observe("protagonist"))})
    game.close()


def _refuse(*args: Any) -> Any:
    raise AssertionError("the walk went through torch")


@pytest.mark.parametrize("config", list(CONFIGS))
def test_copies_acting_together_step_in_numpy_as_torch_does(config: str) -> None:
    """`act_group` of a deterministic victim: each copy's own memory, advanced in NumPy.

    Three copies at three different memories act together; their actions and memories are
    torch's one-row pass (`act`) on each copy, up to rounding; a stochastic victim keeps torch.
    """
    rng = np.random.default_rng(3)
    copies = [_victim(config, steps) for steps in (0, 2, 5)]
    alone = [copy.deepcopy(v) for v in copies]
    for _ in range(4):
        obs = rng.normal(size=(3, 11)) * 3
        together = copies[0].act_group(copies, obs)
        lone = np.stack([v.act(o) for v, o in zip(alone, obs, strict=True)])
        np.testing.assert_allclose(together, lone, rtol=1e-5, atol=1e-5)
    assert copies[0]._group_net() is not None  # the NumPy pass played
    for mine, theirs in zip(copies, alone, strict=True):
        for a, b in zip(mine.hidden_state()["actor"], theirs.hidden_state()["actor"], strict=True):
            torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)
        assert len(mine._seen) == len(theirs._seen)
    stochastic = copy.deepcopy(copies[0])
    stochastic.deterministic = False
    assert stochastic._group_net() is None


def test_an_lstm_cells_step_is_torchs_lstm_row_by_row() -> None:
    from advgame.core.numpy_lstm import LSTMCell

    lstm = nn.LSTM(5, 7)
    g = torch.Generator().manual_seed(0)
    x, h, c = (torch.randn(4, n, generator=g) for n in (5, 7, 7))
    cell = LSTMCell.of(lstm)
    assert cell is not None
    h_np, c_np = cell.step(x.numpy(), h.numpy(), c.numpy())
    for i in range(4):
        with torch.no_grad():
            _, (h_t, c_t) = lstm(x[i : i + 1, None], (h[None, i : i + 1], c[None, i : i + 1]))
        np.testing.assert_allclose(h_np[i], h_t.numpy().reshape(-1), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(c_np[i], c_t.numpy().reshape(-1), rtol=1e-5, atol=1e-6)
