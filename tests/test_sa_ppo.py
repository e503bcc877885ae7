"""SA-PPO: the state-adversarial regulariser, its inner maximisation, and the methods using it."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv

from advgame.agents import sa_ppo
from advgame.agents.sa.ppo import SAPPO, sa_regulariser
from advgame.cli import main


@pytest.fixture
def policy() -> object:
    torch.manual_seed(0)
    torch.set_num_threads(1)
    model = PPO("MlpPolicy", DummyVecEnv([lambda: gym.make("Hopper-v5")]), seed=0, device="cpu")
    return model.policy


def test_the_regulariser_is_zero_at_eps_zero(policy: object) -> None:
    obs = torch.randn(32, 11)
    value, attacked = sa_regulariser(policy, obs, torch.zeros(11), steps=10)
    assert float(value) == 0.0 and torch.equal(attacked, obs)


@pytest.mark.parametrize("walk", ["numpy", "torch"])
def test_the_inner_maximisation_beats_the_best_of_many_random_points(
    policy: object, walk: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[object] = []
    numpy_walk = sa_ppo._numpy_walk

    def spy(*args: object) -> object:
        calls.append(out := numpy_walk(*args) if walk == "numpy" else None)
        return out

    monkeypatch.setattr(sa_ppo, "_numpy_walk", spy)
    torch.manual_seed(1)
    obs, eps = torch.randn(16, 11).clamp(-1.5, 1.5), torch.full((11,), 0.3)
    found, attacked = sa_regulariser(policy, obs, eps, steps=10, low=-1.5, high=1.5)
    assert calls and (calls[0] is not None) == (walk == "numpy")  # a plain MLP walks in numpy
    assert torch.all((attacked - obs).abs() <= eps + 1e-6)  # inside the ball (and the clip)
    assert torch.all(attacked.abs() <= 1.5)
    with torch.no_grad():
        clean = policy.get_distribution(obs).distribution  # type: ignore[attr-defined]
        best = torch.zeros(16)
        for _ in range(200):
            x = (obs + (torch.rand_like(obs) * 2 - 1) * eps).clamp(-1.5, 1.5)
            kl = torch.distributions.kl_divergence(clean, policy.get_distribution(x).distribution)  # type: ignore[attr-defined]
            best = torch.maximum(best, kl.sum(-1))
    assert float(found) >= float(best.mean())


def _learn(cls: type, **kw: object) -> list[np.ndarray]:
    torch.set_num_threads(1)
    env = DummyVecEnv([lambda: gym.make("Hopper-v5")])
    model = cls(
        "MlpPolicy", env, n_steps=256, batch_size=64, n_epochs=2, seed=3, device="cpu", **kw
    )
    model.learn(256)
    return [p.detach().numpy().copy() for p in model.policy.parameters()]


def test_with_kappa_zero_the_update_is_plain_ppos_and_kappa_changes_it() -> None:
    plain = _learn(PPO)
    zero = _learn(SAPPO, sa_kappa=0.0, sa_eps=0.1)
    regularised = _learn(SAPPO, sa_kappa=1.0, sa_eps=0.1, sa_ramp=0.0)
    for a, b in zip(plain, zero, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    assert any(not np.allclose(a, b) for a, b in zip(plain, regularised, strict=True))


@pytest.mark.parametrize("method", ["sa-ppo", "atla-sa"])
def test_the_methods_train_resume_and_evaluate_as_ppo(
    method: str, tmp_path: Path, tiny_atla: Callable[..., list[str]]
) -> None:
    args = tiny_atla(1)
    args[args.index("atla")] = method
    run = tmp_path / method
    assert main(["train", *args, "--run-dir", str(run)]) == 0
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["protagonist_algo"] == "sa-ppo"
    cfg["iterations"] = 2
    (run / "config.json").write_text(json.dumps(cfg))
    assert main(["resume", str(run), "--no-progress"]) == 0
    out = tmp_path / "res"
    ev = ["evaluate", str(run), "--out", str(out), "--seeds", "1", "--workers", "1", "--budgets"]
    assert main([*ev, "--adversaries", "attack:mad"]) == 0
    assert "attack mad" in (out / "report.md").read_text()
