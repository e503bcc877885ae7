"""An SB3 model's policy behind its frozen observation normalizer: what checkpoints play as.

`SB3Policy` acts for one agent (or, through `act_batch`, for the copies of one frozen network
in several games) and is a `advgame.core.policy.WhiteBox` for attacks;
`advgame.agents.common.checkpoint.SB3Checkpoint` builds it from files.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from advgame.core.numpy_net import NetCache, NumpyNet, sb3_modules
from advgame.core.policy import gaussian_mean
from advgame.errors import ConfigError

__all__ = ["SB3Policy"]


class SB3Policy:
    """An SB3 model's policy, behind the observation normalizer it was trained with.

    It is also a `advgame.core.policy.WhiteBox`: attacks may differentiate its networks (PPO's
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
        self._head: Any = None
        self._sampler: Any = None
        self._key: tuple | None = None
        self._stats = (obs_mean, obs_var)
        self._numpy = NetCache()

    @property
    def observation_std(self) -> np.ndarray | None:
        """The normalizer's std: normalized-space budgets (ATLA) are measured in it."""
        return self.std

    def reset(self, seed: int | None = None) -> None:
        """Seed the sampling of a stochastic policy (torch's generator in this process)."""
        if seed is not None and not self.deterministic:
            import torch

            torch.manual_seed(seed)

    @property
    def batch_key(self) -> tuple | None:
        """Equal for policies that `act_batch` may serve together (same frozen net and normalizer).

        ``None`` where `act_batch` could only go row by row: an actor `ActorForward` does not
        cover, or a sampling policy other than a PPO Gaussian.
        """
        self._prepare()
        return self._key

    def act(self, observation: Any) -> Any:
        """The policy's action for one raw observation.

        Normalized in the observation's own precision, then cast to float32, exactly as
        `VecNormalize.normalize_obs` and SB3's ``predict`` do. A Dict observation (goal-
        conditioned tasks, ``MultiInputPolicy``) goes through SB3's ``predict`` unnormalized.
        """
        if isinstance(observation, dict):
            return self._predict_dict(observation)
        return self._predict(self._normalize(np.asarray(observation))[None])[0]

    def act_batch(self, observations: Any) -> Any:
        """The actions for a batch of raw observations ``[n, ...]``.

        Deterministic: row ``i`` is exactly `act`'s, from one batch-invariant forward pass
        (`advgame.agents.common.forward`) where the actor is a plain one, else row by row. Sampling
        (a PPO Gaussian, as the training loop's frozen opponents act): one forward pass and one
        draw of ``[n, action]`` normals from torch's generator: the same distribution as `act`,
        not the same draws as n calls of it (torch fills a long tensor with another algorithm).
        A Dict batch (arrays ``[n, ...]`` per key) goes through SB3's ``predict``.
        """
        if isinstance(observations, dict):
            return self._predict_dict(observations)
        return self._predict(self._normalize(np.asarray(observations)))

    def _predict_dict(self, observation: dict) -> Any:
        """SB3's ``predict`` for a Dict observation (``MultiInputPolicy``), unnormalized."""
        if self.mean is not None:
            raise ConfigError(
                "A Dict observation cannot go through a Box normalizer; train goal-"
                "conditioned protagonists with normalize=False."
            )
        return self.model.predict(observation, deterministic=self.deterministic)[0]

    def _normalize(self, obs: np.ndarray) -> np.ndarray:
        if self.mean is not None and self.std is not None:
            # ndarray.clip: np.clip's ufunc without its dispatch layer (same values)
            obs = ((obs - self.mean) / self.std).clip(-self.clip_obs, self.clip_obs)
        return obs.astype(np.float32, copy=False)

    def _prepare(self) -> None:
        """Once: eval mode, the action box, and the lean forward pass (`ActorForward`)."""
        if self._ready:
            return
        from advgame.agents.common.forward import ActorForward

        policy = self.model.policy
        policy.set_training_mode(False)
        space = self.model.action_space
        self._box = (space.low, space.high) if hasattr(space, "low") else None
        self._squash = bool(getattr(policy, "squash_output", False))
        forward = ActorForward.of(policy)
        self._head = forward if self.deterministic else None
        gaussian = forward is not None and forward.kind == "mean" and hasattr(policy, "log_std")
        self._sampler = forward if gaussian and hasattr(policy, "mlp_extractor") else None
        self._key = None  # no lean forward pass: act row by row
        if (self._head if self.deterministic else self._sampler) is not None:
            self._key = self._network_key()
        self._ready = True

    def _network_key(self) -> tuple:
        """Equal for copies of one frozen network behind one normalizer, acting alike."""
        stats = (id(self._stats[0]), id(self._stats[1]), self.clip_obs)
        return (id(self.model), *stats, self.deterministic)

    def _predict(self, obs: np.ndarray) -> Any:
        """SB3's ``predict`` for a batch of normalized observations, without its checks.

        Frozen opponents call this every step, so the per-call overhead matters: the network
        runs under ``no_grad`` in eval mode, a plain actor skips SB3's distribution objects
        (`ActorForward`; a PPO Gaussian samples ``mean + std * randn`` as SB3's ``rsample``
        does, bit for bit for one row), and a Box action is clipped as SB3 does.
        """
        import torch

        self._prepare()
        policy = self.model.policy
        x = torch.as_tensor(obs)
        if self._head is not None:
            action = self._head(x)
        elif self._sampler is not None:  # SB3's Gaussian sample, the same draws for one row
            mean = self._sampler(x)  # under no_grad inside
            action = mean + torch.randn(mean.shape) * policy.log_std.detach().exp()
        else:
            with torch.no_grad():
                rows = [policy._predict(x[i : i + 1], self.deterministic) for i in range(len(x))]
            action = torch.cat(rows)
        return self._in_box(action.cpu().numpy())

    def _in_box(self, out: np.ndarray) -> np.ndarray:
        """Actions as SB3's ``predict`` returns them: a squashed policy's unscaled, else clipped."""
        if self._box is None:
            return out
        return self.model.policy.unscale_action(out) if self._squash else out.clip(*self._box)

    # -- white-box access (`advgame.core.policy.WhiteBox`): forward passes only, nothing trained ----
    def _features(self, obs: Any) -> Any:
        """Raw observation batch -> the network's input (normalized and clipped as in training)."""
        import torch

        if self.model.policy.training:  # (walking every module each call costs more than the pass)
            self.model.policy.set_training_mode(False)
        if self.mean is None or self.std is None:
            return obs
        mean = torch.as_tensor(self.mean, dtype=torch.float32)
        std = torch.as_tensor(self.std, dtype=torch.float32)
        return ((obs - mean) / std).clamp(-self.clip_obs, self.clip_obs)

    def action_mean(self, obs: Any) -> Any:
        """The mean action (PPO: the Gaussian's mean; SAC/TD3: the deterministic actor's)."""
        policy, x = self.model.policy, self._features(obs)
        mean = gaussian_mean(policy, x)
        if mean is not None:
            return mean
        if hasattr(policy, "get_distribution"):
            return self._gaussian(policy.get_distribution(x).distribution).mean
        if getattr(policy, "actor", None) is None:
            raise ConfigError(f"{type(policy).__name__} has no actor network to attack.")
        if hasattr(policy.actor, "action_dist"):  # SAC: the squashed Gaussian's mode
            return policy.actor(x, deterministic=True)
        return policy.actor(x)

    def numpy_net(self, head: str) -> NumpyNet | None:
        """PPO's mean (``"mean"``) or value head (``"value"``) as a `NumpyNet` behind the normalizer.

        What white-box attacks walk through when they can (the same function as `action_mean` or
        `value`, without torch's per-step overhead); None for SAC, TD3 and policies with layers
        a `NumpyNet` does not cover.
        """
        return self._numpy.get(head, sb3_modules(self.model.policy, head), self._norm_stats())

    @staticmethod
    def _gaussian(dist: Any) -> Any:
        """`dist` (a torch distribution), refused with a clear error unless it is a Gaussian."""
        if not hasattr(dist, "mean") or not hasattr(dist, "stddev"):
            raise ConfigError(
                f"White-box attacks need a Gaussian policy; this one acts through {dist}."
            )
        return dist

    def _norm_stats(self) -> tuple[np.ndarray, np.ndarray, float] | None:
        """The frozen normalizer as a `NumpyNet` applies it: ``(mean, std, clip)``, or None."""
        if self.mean is None or self.std is None:
            return None
        return self.mean, self.std, self.clip_obs

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
