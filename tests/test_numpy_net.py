"""`NumpyNet`: a policy's MLP in NumPy with its input gradient, what white-box attacks walk
through: the same function and gradient as torch's, lone rows in batches, rebuilt on new weights,
and the attacks' NumPy walk scoring what their torch walk scores."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch
from torch import nn

import advgame
from advgame.adversaries import MaxCostAttack, RobustSarsaAttack
from advgame.adversaries.whitebox import CriticAttack, MADAttack
from advgame.adversaries.whitebox_walk import WhiteBoxAttackPolicy
from advgame.agents.common.checkpoint import SB3Policy
from advgame.core.episodes import build_policies
from advgame.core.numpy_net import NumpyNet
from advgame.disruptors import ObservationDisruptor

ADV = "observation_adversary"


@pytest.fixture(scope="module")
def hopper_ppo() -> Any:
    """A PPO on Hopper-v5 after one small update (so its weights are not the initial ones)."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    model = PPO("MlpPolicy", gym.make("Hopper-v5"), n_steps=64, batch_size=32, seed=0, device="cpu")
    model.learn(64)
    return model


def _victim(model: Any) -> SB3Policy:
    rng = np.random.default_rng(0)
    # a tight clip, so that some of the test's inputs are clipped by the normalizer
    return SB3Policy(model, rng.normal(size=11), rng.uniform(0.5, 2.0, 11), clip_obs=2.0)


def _torch_head(victim: Any, head: str, obs: torch.Tensor) -> torch.Tensor:
    return victim.action_mean(obs) if head == "mean" else victim.value(obs)[:, None]


@pytest.mark.parametrize("head", ["mean", "value"])
def test_the_numpy_net_is_the_policys_function_and_gradient(hopper_ppo: Any, head: str) -> None:
    victim = _victim(hopper_ppo)
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


def test_batched_rows_are_lone_rows_and_new_weights_rebuild_it(hopper_ppo: Any) -> None:
    victim = _victim(hopper_ppo)
    net = victim.numpy_net("mean")
    assert net is not None and victim.numpy_net("mean") is net  # built once per weights
    obs = np.random.default_rng(2).normal(size=(17, 11)).astype(np.float32)
    out, tape = net.forward(obs)
    grad = net.backward(tape, np.ones_like(out))
    for i in range(len(obs)):
        lone, lone_tape = net.forward(obs[i : i + 1])
        assert np.array_equal(lone[0], out[i])
        assert np.array_equal(net.backward(lone_tape, np.ones_like(lone))[0], grad[i])
    action_net = hopper_ppo.policy.action_net
    saved = action_net.weight.detach().clone()
    try:
        with torch.no_grad():
            action_net.weight.add_(0.5)  # an update in place, as a learner's optimizer makes
        rebuilt = victim.numpy_net("mean")
        assert rebuilt is not None and rebuilt is not net
        with torch.no_grad():
            now = victim.action_mean(torch.as_tensor(obs)).numpy()
        np.testing.assert_allclose(rebuilt.forward(obs)[0], now, rtol=1e-5, atol=1e-6)
    finally:
        with torch.no_grad():
            action_net.weight.copy_(saved)


def test_what_a_numpy_net_does_not_cover_stays_in_torch() -> None:
    from stable_baselines3 import SAC

    assert NumpyNet.of([nn.Sequential(nn.Linear(3, 4), nn.Sigmoid(), nn.Linear(4, 1))]) is None
    sac = SAC("MlpPolicy", "Pendulum-v1", device="cpu", seed=0)
    assert SB3Policy(sac).numpy_net("mean") is None and SB3Policy(sac).numpy_net("value") is None


def test_saved_team_actors_have_a_numpy_mean() -> None:
    from advgame.core.policy import AgentInfo
    from advgame.workflows import zoo

    game = advgame.make("SafetyHopper-v5")
    spec = zoo.load("safetyhopper/pcrpo")["protagonist"]
    info = AgentInfo(
        "protagonist", game.observation_space("protagonist"), game.action_space("protagonist")
    )
    policy = spec.build(info)
    net = policy.numpy_net("mean")
    assert net is not None and policy.numpy_net("value") is None
    obs = (np.random.default_rng(3).normal(size=(5, 11)) * 2).astype(np.float32)
    with torch.no_grad():
        expected = policy.action_mean(torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(net.forward(obs)[0], expected, rtol=1e-5, atol=1e-6)


ATTACKS = {
    "mad": lambda cache: MADAttack(steps=3),
    "critic": lambda cache: CriticAttack(steps=3),
    "rs": lambda cache: RobustSarsaAttack(steps=3, samples=300, epochs=1, cache_dir=cache),
    "max-cost": lambda cache: MaxCostAttack(steps=3, samples=300, epochs=1, cache_dir=cache),
}


@pytest.mark.parametrize(
    ("name", "space"), [("mad", "raw"), ("mad", "normalized"), ("critic", "raw"),
                        ("critic", "normalized"), ("rs", "raw"), ("max-cost", "normalized")],
)  # fmt: skip
def test_attacks_walk_in_numpy_and_score_what_torch_scores(
    hopper_ppo: Any, name: str, space: str, tmp_path: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    victim, attack = _victim(hopper_ppo), ATTACKS[name](str(tmp_path))
    disruptor = ObservationDisruptor(eps=0.3, space=space)
    game = advgame.make("SafetyHopper-v5", disruptors=[disruptor])  # a cost, for max-cost
    pols = build_policies(game, {"protagonist": victim, ADV: attack})
    if space == "normalized":
        game.set_observation_scale("protagonist", np.linspace(0.5, 2.0, 11))
    game.reset(seed=3)
    policy: WhiteBoxAttackPolicy = pols[ADV]
    torch_walk = policy._torch_walk([policy], "protagonist")

    def refuse(*args: Any) -> Any:
        raise AssertionError("the walk went through torch")

    monkeypatch.setattr(WhiteBoxAttackPolicy, "_torch_walk", refuse)
    walk = policy._walk([policy], "protagonist")
    policy.reset(0)
    policy.act(game.observe(ADV))  # a whole attack, in NumPy
    for u in np.random.default_rng(4).uniform(-1, 1, size=(5, 1, 11)):
        scores, grad = walk(u)
        expected_scores, expected_grad = torch_walk(u)
        np.testing.assert_allclose(scores, expected_scores, rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(grad(), expected_grad(), rtol=1e-4, atol=1e-7)


def test_without_torchs_version_counter_the_stamp_is_the_weights_bytes() -> None:
    from advgame.core.numpy_net import weights_stamp

    class Param:  # a parameter without ``_version`` (what the stamp falls back on)
        def __init__(self, values: np.ndarray) -> None:
            self.values = values

        def detach(self) -> Any:
            return self

        def numpy(self) -> np.ndarray:
            return self.values

    class Module:
        def __init__(self, param: Param) -> None:
            self.param = param

        def parameters(self) -> list[Param]:
            return [self.param]

    module = Module(Param(np.zeros(3, np.float32)))
    before = weights_stamp([module])
    assert weights_stamp([module]) == before
    module.param.values[1] = 1.0  # an update in place
    assert weights_stamp([module]) != before
