"""Stable-Baselines3 checkpoints as policies: what populations store and evaluation loads.

A checkpoint is a ``.zip`` saved by an SB3 model plus, optionally, the observation normalizer
(mean and variance) the policy was trained behind. `SB3Checkpoint` is the picklable spec that
rebuilds it as a `Policy` in any process; `SB3Policy` is that policy.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from advgame.errors import ConfigError
from advgame.policy import AgentInfo

__all__ = ["ALGOS", "SB3Checkpoint", "SB3Policy", "load_model"]

ALGOS = ("ppo", "sac", "td3")


def _algo_class(algo: str) -> Any:
    import stable_baselines3 as sb3

    classes = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}
    if algo not in classes:
        raise ConfigError(f"Unknown algorithm {algo!r}; expected one of {ALGOS}.")
    return classes[algo]


@functools.lru_cache(maxsize=64)
def load_model(path: str, algo: str) -> Any:
    """Load an SB3 model on the CPU (cached per process: evaluation reuses it across cells)."""
    if not Path(path).exists():
        raise ConfigError(f"No checkpoint at {path!r}.")
    return _algo_class(algo).load(path, device="cpu")


class SB3Policy:
    """An SB3 model's policy, behind the observation normalizer it was trained with.

    It is also a `advgame.policy.WhiteBox`: attacks may differentiate its networks (PPO's
    Gaussian actor and value head; SAC's and TD3's actor and Q critic) through the same frozen
    normalizer, without training them.

    Args:
        model: the SB3 model (its ``policy`` is used; nothing is trained).
        obs_mean, obs_var: the frozen normalizer statistics, or None if unnormalized.
        deterministic: act with the distribution's mode instead of sampling.
        clip_obs: the normalizer's clip range (SB3 `VecNormalize` default 10).

    """

    def __init__(
        self,
        model: Any,
        obs_mean: np.ndarray | None = None,
        obs_var: np.ndarray | None = None,
        deterministic: bool = True,
        clip_obs: float = 10.0,
        epsilon: float = 1e-8,
    ) -> None:
        self.model = model
        self.deterministic = deterministic
        self.mean = obs_mean
        self.std = None if obs_var is None else np.sqrt(obs_var + epsilon)
        self.clip_obs = clip_obs
        self._ready = False
        self._box: tuple[np.ndarray, np.ndarray] | None = None
        self._squash = False

    @property
    def observation_std(self) -> np.ndarray | None:
        """The normalizer's std: normalized-space budgets (ATLA) are measured in it."""
        return self.std

    def reset(self, seed: int | None = None) -> None:
        """Seed the sampling of a stochastic policy (torch's generator in this process)."""
        if seed is not None and not self.deterministic:
            import torch

            torch.manual_seed(seed)

    def act(self, observation: Any) -> Any:
        """The policy's action for one raw observation."""
        obs = np.asarray(observation, dtype=np.float32)
        if self.mean is not None and self.std is not None:
            obs = np.clip((obs - self.mean) / self.std, -self.clip_obs, self.clip_obs).astype(
                np.float32
            )
        return self._predict(obs)

    def _predict(self, obs: np.ndarray) -> Any:
        """SB3's ``predict`` for one flat observation, without its batching and checks.

        Frozen opponents call this every step, so the per-call overhead matters: the network
        runs under ``no_grad`` in eval mode and a Box action is clipped as SB3 does.
        """
        import torch

        policy = self.model.policy
        if not self._ready:
            policy.set_training_mode(False)
            space = self.model.action_space
            self._box = (space.low, space.high) if hasattr(space, "low") else None
            self._squash = bool(getattr(policy, "squash_output", False))
            self._ready = True
        with torch.no_grad():
            action = policy._predict(torch.as_tensor(obs[None]), deterministic=self.deterministic)
        out = action.cpu().numpy()[0]
        if self._box is not None:
            out = policy.unscale_action(out) if self._squash else np.clip(out, *self._box)
        return out

    # -- white-box access (`advgame.policy.WhiteBox`): forward passes only, nothing trained ----
    def _features(self, obs: Any) -> Any:
        """Raw observation batch -> the network's input (normalized and clipped as in training)."""
        import torch

        self.model.policy.set_training_mode(False)
        if self.mean is None or self.std is None:
            return obs
        mean = torch.as_tensor(self.mean, dtype=torch.float32)
        std = torch.as_tensor(self.std, dtype=torch.float32)
        return ((obs - mean) / std).clamp(-self.clip_obs, self.clip_obs)

    def action_mean(self, obs: Any) -> Any:
        """The mean action (PPO: the Gaussian's mean; SAC/TD3: the deterministic actor's)."""
        policy, x = self.model.policy, self._features(obs)
        if hasattr(policy, "get_distribution"):
            dist = policy.get_distribution(x).distribution
            if not hasattr(dist, "mean") or not hasattr(dist, "stddev"):
                raise ConfigError(
                    f"White-box attacks need a Gaussian policy; this one acts through {dist}."
                )
            return dist.mean
        if getattr(policy, "actor", None) is None:
            raise ConfigError(f"{type(policy).__name__} has no actor network to attack.")
        if hasattr(policy.actor, "action_dist"):  # SAC: the squashed Gaussian's mode
            return policy.actor(x, deterministic=True)
        return policy.actor(x)

    def action_std(self) -> Any:
        """PPO's state-independent action std; ``None`` for SAC/TD3 (attacked through means)."""
        log_std = getattr(self.model.policy, "log_std", None)
        return None if log_std is None else log_std.detach().exp()

    def value(self, obs: Any) -> Any:
        """PPO's value head ``V(obs)``; ``None`` for SAC/TD3."""
        policy = self.model.policy
        if not hasattr(policy, "predict_values"):
            return None
        return policy.predict_values(self._features(obs)).squeeze(-1)

    def q_value(self, obs: Any, action: Any) -> Any:
        """SAC's/TD3's critic ``min_i Q_i(obs, action)``; ``None`` for PPO."""
        import torch

        critic = getattr(self.model.policy, "critic", None)
        if critic is None:
            return None
        qs = critic(self._features(obs), action)
        return torch.min(torch.cat(qs, dim=-1), dim=-1).values


@dataclass(frozen=True)
class SB3Checkpoint:
    """A saved SB3 model (and normalizer) as a picklable policy spec.

    Example:
        ``SB3Checkpoint("runs/demo/checkpoints/iter_0004/protagonist.zip", algo="ppo")``

    """

    path: str
    """The model ``.zip``."""
    algo: str = "ppo"
    """``"ppo"``, ``"sac"`` or ``"td3"``."""
    normalizer: str | None = None
    """An ``.npz`` with ``mean`` and ``var`` of the observation normalizer, if any."""
    deterministic: bool = True
    """Act with the mode of the action distribution."""

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ConfigError(f"SB3Checkpoint.algo must be one of {ALGOS}, got {self.algo!r}.")

    def build(self, info: AgentInfo) -> SB3Policy:
        """Load the model (cached per process) and check it fits `info`'s spaces."""
        model = load_model(str(self.path), self.algo)
        if model.observation_space.shape != info.observation_space.shape:
            raise ConfigError(
                f"Checkpoint {self.path} observes shape {model.observation_space.shape}, but "
                f"{info.agent!r} observes {info.observation_space.shape}."
            )
        mean = var = None
        if self.normalizer is not None:
            stats = np.load(self.normalizer)
            mean, var = stats["mean"], stats["var"]
        return SB3Policy(model, mean, var, deterministic=self.deterministic)
