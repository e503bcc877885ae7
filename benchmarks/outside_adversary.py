"""An observation adversary written without advgame: plain Gymnasium and Stable-Baselines3.

The yardstick of issue 36. A Gymnasium env whose action moves a frozen victim's *normalized*
observation by at most ``eps`` in L∞ (ATLA's threat model: eps 0.075 on Hopper, 0.05 on
Walker2d); the adversary observes the true state and is paid minus the victim's reward. It is
trained with SB3's PPO (4 envs, VecNormalize of observations and rewards, ``n_steps=512``,
``batch_size=64``, ``ent_coef=0``, otherwise SB3's defaults). Nothing here imports advgame, so
a weakness of advgame's learners cannot hide in both sides of the comparison.

The victim is an SB3 PPO zip and its observation statistics (an ``.npz`` with ``mean`` and
``var``, as advgame's zoo ships them); it acts deterministically on
``clip((obs + delta - mean) / sqrt(var + 1e-8), -10, 10)`` with ``delta = eps * u * sqrt(var +
1e-8)`` for the adversary's action ``u`` in ``[-1, 1]^n``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

EPSILON = 1e-8
"""VecNormalize's epsilon: the std of a normalized observation is sqrt(var + EPSILON)."""


class PerturbedVictimEnv(gym.Env):
    """The adversary's view: true state in, a bounded perturbation of the victim's input out."""

    def __init__(self, env_id: str, victim_zip: str, victim_norm: str, eps: float) -> None:
        from stable_baselines3 import PPO

        self.env = gym.make(env_id)
        self.victim = PPO.load(victim_zip, device="cpu")
        stats = np.load(victim_norm)
        self.mean, self.std = stats["mean"], np.sqrt(stats["var"] + EPSILON)
        self.eps = float(eps)
        self.observation_space = self.env.observation_space
        n = self.env.observation_space.shape[0]
        self.action_space = gym.spaces.Box(-1.0, 1.0, (n,), np.float32)
        self._obs: np.ndarray | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[Any, dict]:
        """Reset the task; the adversary sees its first true state."""
        self._obs, info = self.env.reset(seed=seed)
        return self._obs, info

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict]:
        """The victim acts on the perturbed observation; the adversary is paid minus its reward."""
        u = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        seen = np.clip((self._obs + self.eps * u * self.std - self.mean) / self.std, -10.0, 10.0)
        act, _ = self.victim.predict(seen.astype(np.float32), deterministic=True)
        self._obs, reward, terminated, truncated, info = self.env.step(act)
        return self._obs, -float(reward), terminated, truncated, {**info, "victim_reward": reward}


def train(
    env_id: str, victim_zip: str, victim_norm: str, eps: float, steps: int, seed: int, out: Path
) -> dict[str, str]:
    """Train the adversary `steps` steps; save ``adversary.zip`` and its obs statistics."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(1)
    venv = make_vec_env(
        lambda: PerturbedVictimEnv(env_id, victim_zip, victim_norm, eps), n_envs=4, seed=seed
    )
    venv = VecNormalize(venv, norm_obs=True, norm_reward=True)
    model = PPO(
        "MlpPolicy", venv, n_steps=512, batch_size=64, ent_coef=0.0, seed=seed, device="cpu"
    )
    model.learn(steps)
    out.mkdir(parents=True, exist_ok=True)
    model.save(out / "adversary.zip")
    np.savez(out / "adversary_obs_norm.npz", mean=venv.obs_rms.mean, var=venv.obs_rms.var)
    venv.close()
    return {"path": str(out / "adversary.zip"), "normalizer": str(out / "adversary_obs_norm.npz")}


def evaluate(
    env_id: str, victim_zip: str, victim_norm: str, eps: float, adversary: dict[str, str],
    seeds: list[int],
) -> list[float]:  # fmt: skip
    """The victim's true return per seed, both sides deterministic (``adversary``: `train`'s)."""
    from stable_baselines3 import PPO

    env = PerturbedVictimEnv(env_id, victim_zip, victim_norm, eps)
    model = PPO.load(adversary["path"], device="cpu")
    stats = np.load(adversary["normalizer"])
    mean, std = stats["mean"], np.sqrt(stats["var"] + EPSILON)
    returns = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            u, _ = model.predict(np.clip((obs - mean) / std, -10, 10), deterministic=True)
            obs, _, terminated, truncated, info = env.step(u)
            total += float(info["victim_reward"])
            done = terminated or truncated
        returns.append(total)
    return returns
