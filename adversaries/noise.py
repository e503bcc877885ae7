"""Random adversaries: the paper's random disturbance mode, and the no-op."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from advgame.core.policy import AgentInfo, ConstantPolicy, Policy
from advgame.errors import ConfigError

__all__ = ["GaussianAdversary", "UniformAdversary", "ZeroAdversary"]


@dataclass(frozen=True)
class ZeroAdversary:
    """The no-op adversary: its disruptor leaves the task unchanged (the nominal game).

    Example:
        >>> import advgame
        >>> game = advgame.make("Hopper-v5")
        >>> ZeroAdversary().build(game.agent_info("observation_adversary")).act(None)
        array([0., 0., 0., 0., 0., 0., 0., 0., 0., 0., 0.], dtype=float32)

    """

    def build(self, info: AgentInfo) -> Policy:
        """A constant policy sending the disruptor's identity action."""
        return ConstantPolicy(info.noop_action)


class _NoisePolicy:
    """Draws raw perturbations and encodes them into the adversary's action.

    Samples are drawn and encoded in blocks of `BLOCK` (one generator call per block), which is
    as reproducible as drawing one at a time and keeps the per-step cost off the hot path.
    """

    BLOCK = 256

    def __init__(self, info: AgentInfo, draw: Any) -> None:
        self.info = info
        self.draw = draw
        self.rng = np.random.default_rng()
        self._rows: list[np.ndarray] = []  # the block's rows, split once per block
        self._i = 0

    def reset(self, seed: int | None = None) -> None:
        """Reseed (when a seed is given), dropping samples drawn from the old seed."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
            self._i = len(self._rows)

    def act(self, observation: Any) -> np.ndarray:
        """The next encoded noise sample."""
        i = self._i
        if i >= len(self._rows):
            self._rows = list(self.info.encode(self.draw(self.rng, self.BLOCK)))
            i = 0
        self._i = i + 1
        return self._rows[i]


def _vector(value: float | Sequence[float], size: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim > 1 or (arr.ndim == 1 and arr.size != size) or not np.isfinite(arr).all():
        raise ConfigError(f"{name} must be a finite scalar or {size} values, got {value!r}.")
    return np.broadcast_to(arr, (size,)).copy()


@dataclass(frozen=True)
class GaussianAdversary:
    """Perturbation ``~ N(mean, std)`` per dimension, in the disruptor's raw units.

    With an unbounded disruptor (``bounded=False``) this is the paper's random mode exactly;
    with a bounded one the sample is clipped into the budget (and the clip counted).

    Example:
        >>> import advgame
        >>> game = advgame.make("Hopper-v5", preset="state-gauss-0.1")
        >>> pol = GaussianAdversary(std=0.1).build(game.agent_info("observation_adversary"))
        >>> pol.reset(seed=0); pol.act(None).shape
        (11,)

    """

    mean: float | Sequence[float] = 0.0
    """Mean of the perturbation (raw units)."""
    std: float | Sequence[float] = 0.1
    """Standard deviation (raw units); the paper's σ = 0.1 or 0.15."""

    def __post_init__(self) -> None:
        if np.any(np.asarray(self.std, dtype=np.float64) < 0):
            raise ConfigError(f"GaussianAdversary.std must be >= 0, got {self.std!r}.")

    def build(self, info: AgentInfo) -> Policy:
        """A seeded Gaussian sampler for `info`'s disruptor."""
        n = info.action_size
        mean, std = _vector(self.mean, n, "mean"), _vector(self.std, n, "std")
        return _NoisePolicy(info, lambda rng, k: rng.normal(mean, std, size=(k, n)))


@dataclass(frozen=True)
class UniformAdversary:
    """Perturbation ``~ U(low, high)`` per dimension, in raw units (the paper's ``U[0.2, 0.8]``).

    With a once-per-episode schedule this is the appendix's uniform initial draw of a shift.

    Example:
        >>> import advgame
        >>> game = advgame.make("Ant-v5", preset="shift-uniform")
        >>> pol = UniformAdversary(low=(9.81, 0.8), high=(19.82, 1.2)).build(
        ...     game.agent_info("dynamics_adversary"))
        >>> pol.reset(seed=0); pol.act(None).shape
        (2,)

    """

    low: float | Sequence[float] = -0.1
    """Lower end per dimension (raw units)."""
    high: float | Sequence[float] = 0.1
    """Upper end per dimension (raw units)."""

    def __post_init__(self) -> None:
        if np.any(np.asarray(self.low, dtype=np.float64) > np.asarray(self.high, dtype=np.float64)):
            raise ConfigError(
                f"UniformAdversary needs low <= high, got {self.low!r} > {self.high!r}."
            )

    def build(self, info: AgentInfo) -> Policy:
        """A seeded uniform sampler for `info`'s disruptor."""
        n = info.action_size
        low, high = _vector(self.low, n, "low"), _vector(self.high, n, "high")
        return _NoisePolicy(info, lambda rng, k: rng.uniform(low, high, size=(k, n)))


class _UniformActions:
    """Samples the action box itself (no encoding), in seeded blocks."""

    BLOCK = 256

    def __init__(self, low: np.ndarray, high: np.ndarray) -> None:
        self.low, self.high = low, high
        self.rng = np.random.default_rng()
        self._block = np.empty((0, *low.shape), dtype=np.float32)
        self._i = 0

    def reset(self, seed: int | None = None) -> None:
        """Reseed (when a seed is given)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
            self._i = len(self._block)

    def act(self, observation: Any) -> np.ndarray:
        """The next uniform action."""
        if self._i >= len(self._block):
            size = (self.BLOCK, *self.low.shape)
            self._block = self.rng.uniform(self.low, self.high, size=size).astype(np.float32)
            self._i = 0
        self._i += 1
        return self._block[self._i - 1]


@dataclass(frozen=True)
class RandomAdversary:
    """Uniform over the adversary's whole action space: random noise that fills the budget.

    The fair random baseline for a learned adversary: the same budget, no intelligence.

    Example:
        >>> import advgame
        >>> game = advgame.make("Hopper-v5", preset="atla")
        >>> pol = RandomAdversary().build(game.agent_info("observation_adversary"))
        >>> pol.reset(seed=0); bool(abs(pol.act(None)).max() <= 1.0)
        True

    """

    def build(self, info: AgentInfo) -> Policy:
        """A seeded sampler of the adversary's (bounded) action space."""
        space = info.action_space
        low = np.asarray(getattr(space, "low", np.nan), dtype=np.float64)
        high = np.asarray(getattr(space, "high", np.nan), dtype=np.float64)
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
            raise ConfigError(
                f"RandomAdversary needs a bounded Box action space; {info.agent!r} has {space} "
                "(for an unbounded disruptor use GaussianAdversary)."
            )
        return _UniformActions(low, high)
