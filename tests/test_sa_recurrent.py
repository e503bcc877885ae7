"""ATLA-LSTM-SA: the sequence SA regulariser, SARecurrentPPO's update, and the method end to end."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces
from sb3_contrib import RecurrentPPO
from sb3_contrib.ppo_recurrent.policies import MlpLstmPolicy
from stable_baselines3.common.vec_env import DummyVecEnv

import advgame
from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.agents.common.recurrent_policy import RecurrentSB3Policy
from advgame.agents.recurrent.ppo import UnrolledRecurrentPPO
from advgame.agents.sa.recurrent import SARecurrentPPO, recurrent_sa_regulariser
from advgame.cli import main
from advgame.errors import ConfigError
from advgame.training.config import METHODS, learner_config

LENGTHS = (6, 4, 5)
"""Three sequences, padded to 6 steps: the 2nd and 3rd end in padding."""
STARTS = (1.0, 0.0, 1.0)
"""Whether each sequence opens an episode (its stored LSTM state is then zeroed)."""
EPS, LOW, HIGH = 0.3, -1.5, 1.5


@pytest.fixture
def policy() -> Any:
    """A tiny LSTM policy (4 inputs, 8 units, 2 actions) whose means move visibly with δ."""
    torch.manual_seed(0)
    torch.set_num_threads(1)
    box = spaces.Box(-np.inf, np.inf, (4,), np.float32)
    act = spaces.Box(-1.0, 1.0, (2,), np.float32)
    pol: Any = MlpLstmPolicy(box, act, lambda _: 1e-3, net_arch=[8], lstm_hidden_size=8)
    with torch.no_grad():
        pol.action_net.weight.mul_(100.0)
        pol.log_std.fill_(-0.5)
    return pol


def _batch(garbage: float = 0.0) -> dict[str, Any]:
    """RecurrentPPO's minibatch layout: padded sequences flattened, states at their starts."""
    gen = torch.Generator().manual_seed(1)
    obs = torch.randn(3, 6, 4, generator=gen).clamp(LOW, HIGH)
    mask = torch.zeros(3, 6)
    starts = torch.zeros(3, 6)
    for i, (length, start) in enumerate(zip(LENGTHS, STARTS, strict=True)):
        mask[i, :length] = 1.0
        obs[i, length:] = garbage  # sb3-contrib pads with 0
        starts[i, 0] = start
    states = (torch.randn(1, 3, 8, generator=gen), torch.randn(1, 3, 8, generator=gen))
    return {"obs": obs.reshape(18, 4), "states": states, "starts": starts.reshape(18),
            "mask": mask.reshape(18) > 0}  # fmt: skip


def _regulariser(policy: Any, steps: int, seed: int = 2, **kw: Any) -> tuple[Any, Any]:
    b = _batch(**kw)
    torch.manual_seed(seed)
    eps = torch.full((4,), EPS)
    return recurrent_sa_regulariser(
        policy, b["obs"], b["states"], b["starts"], b["mask"], eps, steps, LOW, HIGH
    )


def _hand_means(policy: Any, obs: torch.Tensor) -> list[torch.Tensor]:
    """Each sequence's action means, its LSTM run step by step from its (zeroed) state."""
    b, out = _batch(), []
    for i, (length, start) in enumerate(zip(LENGTHS, STARTS, strict=True)):
        h, c = b["states"][0][:, i : i + 1], b["states"][1][:, i : i + 1]
        h, c = h * (1 - start), c * (1 - start)
        means = []
        for x in obs.reshape(3, 6, 4)[i, :length]:
            y, (h, c) = policy.lstm_actor(x.view(1, 1, 4), (h, c))
            means.append(policy.action_net(policy.mlp_extractor.forward_actor(y[0])))
        out.append(torch.cat(means))
    return out


def test_at_zero_steps_the_value_is_the_kl_at_the_random_start_by_hand(policy: Any) -> None:
    value, attacked = _regulariser(policy, steps=0)
    clean = torch.cat(_hand_means(policy, _batch()["obs"]))
    moved = torch.cat(_hand_means(policy, attacked))
    var = torch.exp(2 * policy.log_std.detach())
    by_hand = ((moved - clean) ** 2 / (2 * var)).sum(-1).mean().detach()  # equal stds: mean term
    assert float(by_hand) > 1e-3
    torch.testing.assert_close(value.detach(), by_hand, rtol=1e-5, atol=1e-7)


def test_the_walk_stays_in_the_ball_and_clip_and_leaves_padding_alone(policy: Any) -> None:
    obs, mask = _batch()["obs"], _batch()["mask"]
    _, attacked = _regulariser(policy, steps=5)
    assert torch.all((attacked - obs).abs() <= EPS + 1e-6)
    assert torch.all((attacked >= LOW) & (attacked <= HIGH))
    assert torch.equal(attacked[~mask], obs[~mask])
    assert torch.all((attacked - obs)[mask].abs().amax(-1) > 0)


def test_padded_steps_do_not_change_the_value(policy: Any) -> None:
    for steps in (0, 3):
        padded_zero, _ = _regulariser(policy, steps)
        padded_junk, _ = _regulariser(policy, steps, garbage=1.4)
        torch.testing.assert_close(padded_zero, padded_junk, rtol=1e-6, atol=1e-8)


def test_the_walk_increases_the_kl_over_its_start_and_beats_random_points(policy: Any) -> None:
    start, walked = (_regulariser(policy, steps)[0].item() for steps in (0, 10))
    best_random = max(_regulariser(policy, 0, seed=s)[0].item() for s in range(10, 60))
    assert walked > start
    assert walked >= best_random


def test_the_gradient_reaches_the_lstm_and_the_std(policy: Any) -> None:
    value, _ = _regulariser(policy, steps=2)
    value.backward()
    for param in (policy.lstm_actor.weight_ih_l0, policy.lstm_actor.weight_hh_l0,
                  policy.action_net.weight, policy.log_std):  # fmt: skip
        assert param.grad is not None and float(param.grad.abs().sum()) > 0


def _one_update(cls: type, **kw: Any) -> list[np.ndarray]:
    """Parameters after one rollout (an episode ends inside it) and one ``train()``."""
    torch.set_num_threads(1)
    env = DummyVecEnv([lambda: gym.make("Pendulum-v1")])
    model = cls(
        "MlpLstmPolicy", env, n_steps=256, batch_size=64, n_epochs=2, seed=3, device="cpu",
        policy_kwargs={"lstm_hidden_size": 16, "net_arch": [16]}, **kw,
    )  # fmt: skip
    model.learn(256)
    return [p.detach().numpy().copy() for p in model.policy.parameters()]


@pytest.mark.parametrize("extra", [{}, {"clip_range_vf": 0.2, "target_kl": 1e-4}])
def test_with_kappa_zero_the_update_is_recurrent_ppos_and_kappa_changes_it(
    extra: dict[str, float],
) -> None:
    plain = _one_update(UnrolledRecurrentPPO, **extra)  # the plain LSTM learner advgame trains
    zero = _one_update(SARecurrentPPO, sa_kappa=0.0, sa_eps=0.1, **extra)
    regularised = _one_update(SARecurrentPPO, sa_kappa=1.0, sa_eps=0.1, sa_ramp=0.0, **extra)
    for a, b in zip(plain, zero, strict=True):
        np.testing.assert_array_equal(a, b)
    assert any(not np.array_equal(a, b) for a, b in zip(plain, regularised, strict=True))


def test_the_config_checks_both_parents_and_saves_as_recurrent_ppo() -> None:
    cfg = learner_config("sa-recurrent-ppo", {"sa_eps": 0.05})
    assert cfg.algo == "recurrent-ppo" and cfg.model_class() is SARecurrentPPO
    assert (cfg.sa_kappa, cfg.sa_steps, cfg.sa_eps, cfg.lstm_hidden_size) == (0.6, 2, 0.05, 64)
    for bad in ({"sa_kappa": -1.0}, {"sa_space": "pixels"}, {"lstm_hidden_size": 0}):
        with pytest.raises(ConfigError):
            learner_config("sa-recurrent-ppo", bad)
    method = METHODS["atla-lstm-sa"]
    assert method["protagonist_algo"] == "sa-recurrent-ppo"
    assert method["adversary_algo"] == METHODS["atla-lstm"]["adversary_algo"] == "recurrent-ppo"


def test_the_method_trains_resumes_evaluates_and_plays_as_recurrent_ppo(
    tmp_path: Path, tiny_atla: Callable[..., list[str]]
) -> None:
    args = tiny_atla(1)
    args[args.index("atla")] = "atla-lstm-sa"
    run = tmp_path / "run"
    assert main(["train", *args, "--run-dir", str(run)]) == 0
    cfg = json.loads((run / "config.json").read_text())
    assert (cfg["protagonist_algo"], cfg["adversary_algo"]) == ("sa-recurrent-ppo", "recurrent-ppo")
    cfg["iterations"] = 2
    (run / "config.json").write_text(json.dumps(cfg))
    assert main(["resume", str(run), "--no-progress"]) == 0
    out = tmp_path / "res"
    ev = ["evaluate", str(run), "--out", str(out), "--seeds", "1", "--workers", "1", "--budgets"]
    assert main([*ev, "--adversaries", "attack:mad"]) == 0
    assert "attack mad" in (out / "report.md").read_text()
    folder = run / "checkpoints" / "iter_0002"
    saved: Any = RecurrentPPO.load(folder / "protagonist.zip", device="cpu")
    assert type(saved) is RecurrentPPO and vars(saved)["sa_kappa"] == 0.6  # sa_* ride along
    spec = SB3Checkpoint(
        str(folder / "protagonist.zip"), "recurrent-ppo", str(folder / "protagonist_obs_norm.npz")
    )
    game = advgame.make("Hopper-v5", preset="atla")
    player = spec.build(game.agent_info("protagonist"))
    assert isinstance(player, RecurrentSB3Policy)
    player.reset(seed=0)
    obs, _ = game.reset(seed=0)
    assert game.action_space("protagonist").contains(player.act(obs["protagonist"]))
