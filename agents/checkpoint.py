"""Stable-Baselines3 checkpoints as policies: what populations store and evaluation loads.

A checkpoint is a ``.zip`` saved by an SB3 model plus, optionally, the observation normalizer
the policy was trained behind: the project's ``*_obs_norm.npz`` (``mean`` and ``var``) or a
`VecNormalize` pickle saved by plain SB3 (``VecNormalize.save``), read by `load_normalizer`.
`SB3Checkpoint` is the picklable spec that rebuilds it as a `Policy` in any process;
`SB3Policy` is that policy.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from advgame.core.files import reading
from advgame.core.numpy_net import NetCache, NumpyNet, sb3_modules
from advgame.core.policy import AgentInfo, gaussian_mean
from advgame.errors import ConfigError, FileFormatError

__all__ = ["ALGOS", "Normalizer", "SB3Checkpoint", "SB3Policy", "load_model", "load_normalizer"]

ALGOS = ("ppo", "sac", "td3", "ompo", "dbc", "rsc")
CHECKPOINT_FIX = (
    "Save it again from the model (or rerun the training iteration that wrote it); a copy "
    "cut short in transfer loads once copied whole."
)
"""How to recover from a damaged checkpoint or normalizer file."""


def _algo_class(algo: str) -> Any:
    """The SB3 class that loads a checkpoint of `algo`.

    SB3's own for PPO, SAC and TD3; otherwise the class its learner config trains
    (``model_class``: OMPO, DBC, RSC), so a new learner registers in one place.
    """
    import stable_baselines3 as sb3

    from advgame.agents.learners import LEARNERS

    if algo not in ALGOS:
        raise ConfigError(f"Unknown algorithm {algo!r}; expected one of {ALGOS}.")
    classes = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}
    return classes[algo] if algo in classes else LEARNERS[algo].model_class()


@functools.lru_cache(maxsize=64)
def load_model(path: str, algo: str) -> Any:
    """Load an SB3 model on the CPU (cached per process: evaluation reuses it across cells).

    A policy is loaded to act, not to train on: a HER replay buffer (which SB3 can build only
    with an env) is replaced by the plain one, so HER checkpoints load without their env.
    """
    if not Path(path).exists():
        raise ConfigError(f"No checkpoint at {path!r}.")
    plain: dict[str, Any] = {
        "replay_buffer_class": None,
        "replay_buffer_kwargs": {},
    }  # only where saved (SAC/TD3)
    cls = _algo_class(algo)
    with reading(path, f"{algo.upper()} checkpoint", CHECKPOINT_FIX):
        return cls.load(path, device="cpu", custom_objects=plain)


@dataclass(frozen=True)
class Normalizer:
    """Frozen observation-normalizer statistics, as SB3's `VecNormalize` applies them."""

    mean: np.ndarray
    """Running mean of the raw observations."""
    var: np.ndarray
    """Running variance of the raw observations."""
    clip_obs: float = 10.0
    """Normalized observations are clipped to ``[-clip_obs, clip_obs]``."""
    epsilon: float = 1e-8
    """Added to the variance before its square root."""


def load_normalizer(path: str) -> Normalizer | None:
    """Read a normalizer: an ``.npz`` (``mean``, ``var``) or a `VecNormalize` pickle.

    Returns None for a `VecNormalize` saved with ``norm_obs=False`` (raw observations). Cached
    per process and file version. Only load pickles you trust: unpickling runs code.
    """
    if not Path(path).is_file():
        raise ConfigError(
            f"No normalizer file at {path!r}; give the `VecNormalize.save` pickle or the "
            "``*_obs_norm.npz`` saved beside the model."
        )
    return _read_normalizer(path, Path(path).stat().st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _read_normalizer(path: str, mtime_ns: int) -> Normalizer | None:
    if path.endswith(".npz"):
        with reading(path, "observation normalizer", CHECKPOINT_FIX), np.load(path) as stats:
            if "mean" not in stats or "var" not in stats:
                raise FileFormatError(
                    f"The observation normalizer {path} holds {list(stats)}; expected 'mean' and "
                    f"'var' (written by another program?). {CHECKPOINT_FIX}",
                    path=path,
                )
            return Normalizer(np.asarray(stats["mean"]), np.asarray(stats["var"]))
    return _vecnormalize_stats(path)


def _vecnormalize_stats(path: str) -> Normalizer | None:
    import pickle

    from stable_baselines3.common.running_mean_std import RunningMeanStd

    fix = (
        "Expected a VecNormalize pickle (`VecNormalize.save`) or an .npz with 'mean' and 'var'; "
        + CHECKPOINT_FIX
    )
    with reading(path, "VecNormalize normalizer", fix), open(path, "rb") as f:
        norm = pickle.load(f)
    rms = getattr(norm, "obs_rms", None)
    if not isinstance(rms, RunningMeanStd):
        raise ConfigError(
            f"{path} holds {type(norm).__name__} with obs_rms {type(rms).__name__}; expected a "
            "VecNormalize of a Box observation space (Dict observations are not supported)."
        )
    if not getattr(norm, "norm_obs", True):
        return None
    return Normalizer(rms.mean, rms.var, float(norm.clip_obs), float(norm.epsilon))


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
        (`advgame.agents.forward`) where the actor is a plain one, else row by row. Sampling
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
        from advgame.agents.forward import ActorForward

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
            stats = (id(self._stats[0]), id(self._stats[1]), self.clip_obs)
            self._key = (id(self.model), *stats, self.deterministic)
        self._ready = True

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
        out = action.cpu().numpy()
        if self._box is not None:
            out = policy.unscale_action(out) if self._squash else out.clip(*self._box)
        return out

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

    def numpy_net(self, head: str) -> NumpyNet | None:
        """PPO's mean (``"mean"``) or value head (``"value"``) as a `NumpyNet` behind the normalizer.

        What white-box attacks walk through when they can (the same function as `action_mean` or
        `value`, without torch's per-step overhead); None for SAC, TD3 and policies with layers
        a `NumpyNet` does not cover.
        """
        norm = None
        if self.mean is not None and self.std is not None:
            norm = (self.mean, self.std, self.clip_obs)
        return self._numpy.get(head, sb3_modules(self.model.policy, head), norm)

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
    """The observation normalizer, if any: an ``.npz`` with ``mean`` and ``var`` or a
    `VecNormalize` pickle (see `load_normalizer`)."""
    deterministic: bool = True
    """Act with the mode of the action distribution."""

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ConfigError(f"SB3Checkpoint.algo must be one of {ALGOS}, got {self.algo!r}.")

    def build(self, info: AgentInfo) -> SB3Policy:
        """Load the model and normalizer (cached per process); check they fit `info`'s spaces."""
        model = load_model(str(self.path), self.algo)
        for what in ("observation", "action"):
            have, want = getattr(model, f"{what}_space"), getattr(info, f"{what}_space")
            if have.shape != want.shape or type(have) is not type(want):
                raise ConfigError(
                    f"Checkpoint {self.path} has {what} space {have}, but {info.agent!r} has "
                    f"{want}; evaluate it on a scenario with the spaces it was trained on."
                )
        norm = load_normalizer(str(self.normalizer)) if self.normalizer is not None else None
        if norm is None:
            return SB3Policy(model, deterministic=self.deterministic)
        if norm.mean.shape != info.observation_space.shape:
            raise ConfigError(
                f"The normalizer {self.normalizer} has shape {norm.mean.shape}, but "
                f"{info.agent!r} observes {info.observation_space.shape}; give the normalizer "
                f"saved with {self.path}."
            )
        return SB3Policy(
            model, norm.mean, norm.var, self.deterministic, norm.clip_obs, norm.epsilon
        )
