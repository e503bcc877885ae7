"""The multi-agent learners' normalizers, with SB3 `VecNormalize`'s semantics.

* `RunningNorm`: a running mean/variance of observations.
* `RewardScaler`: divides each agent's reward by the std of its discounted return (SB3's reward
  normalization), one running statistic per protagonist.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

__all__ = ["RewardScaler", "RunningNorm"]


class RunningNorm:
    """Running mean and variance of a stream of batches (Chan et al.'s parallel update).

    `normalize` maps ``x`` to ``clip((x - mean) / sqrt(var + epsilon), ±clip)``, as SB3's
    `VecNormalize` does, so saved statistics mean the same thing in both.
    """

    def __init__(self, shape: Sequence[int], clip: float = 10.0, epsilon: float = 1e-8) -> None:
        self.mean = np.zeros(tuple(shape), dtype=np.float64)
        self.var = np.ones(tuple(shape), dtype=np.float64)
        self.count = 1e-4
        self.clip = float(clip)
        self.epsilon = float(epsilon)

    def update(self, batch: np.ndarray) -> None:
        """Fold a batch (leading axis = samples) into the statistics."""
        n = batch.shape[0]
        mean = batch.sum(axis=0) / n  # sum/n and the square below: cheaper than mean()/var()
        centred = batch - mean
        var = (centred * centred).sum(axis=0) / n
        delta, total = mean - self.mean, self.count + n
        self.mean = self.mean + delta * n / total
        m2 = self.var * self.count + var * n + delta**2 * self.count * n / total
        self.var, self.count = m2 / total, total

    @property
    def std(self) -> np.ndarray:
        """``sqrt(var + epsilon)``: what observations are divided by."""
        return np.sqrt(self.var + self.epsilon)

    def normalize(self, x: np.ndarray) -> np.ndarray:
        """Standardize and clip `x` (float32)."""
        return np.clip((x - self.mean) / self.std, -self.clip, self.clip).astype(np.float32)

    def subset(self, index: slice) -> RunningNorm:
        """A copy holding the statistics of the components `index` selects."""
        part = RunningNorm(self.mean[index].shape, self.clip, self.epsilon)
        part.mean, part.var, part.count = (
            self.mean[index].copy(),
            self.var[index].copy(),
            self.count,
        )
        return part

    def state_dict(self) -> dict[str, Any]:
        """The statistics as tensors (for ``torch.save(..., weights_only=True)`` files)."""
        return {
            "mean": torch.from_numpy(self.mean.copy()),
            "var": torch.from_numpy(self.var.copy()),
            "count": float(self.count),
            "clip": self.clip,
            "epsilon": self.epsilon,
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore statistics written by `state_dict`."""
        self.mean = state["mean"].numpy().astype(np.float64)
        self.var = state["var"].numpy().astype(np.float64)
        self.count = float(state["count"])
        self.clip, self.epsilon = float(state["clip"]), float(state["epsilon"])


class RewardScaler:
    """Scale each agent's reward by the running std of its discounted return (not its mean)."""

    def __init__(self, n_envs: int, n_agents: int, gamma: float, clip: float = 10.0) -> None:
        self.returns = np.zeros((n_envs, n_agents))
        self.rms = RunningNorm((n_agents,), clip=clip)
        self.gamma = gamma

    def __call__(self, rewards: np.ndarray, dones: np.ndarray, update: bool) -> np.ndarray:
        """Scaled `rewards` ``[envs, agents]``; `dones` ``[envs]`` ends the tracked returns."""
        self.returns = self.returns * self.gamma + rewards
        if update:
            self.rms.update(self.returns)
        scaled = np.clip(rewards / self.rms.std, -self.rms.clip, self.rms.clip)
        self.returns[dones] = 0.0
        return scaled.astype(np.float32)
