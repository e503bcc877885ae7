"""Scheduled adversaries: deterministic shifts, constant or sinusoidal per episode (paper appendix)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from advgame.core.policy import AgentInfo, ConstantPolicy, Policy
from advgame.errors import ConfigError

__all__ = ["ConstantAdversary", "SinusoidAdversary"]


@dataclass(frozen=True)
class ConstantAdversary:
    """Always the same perturbation or parameter value, in raw units.

    The appendix's deterministic shift of Ant is ``ConstantAdversary((14.715, 1.0))`` on a
    (gravity, wind) dynamics disruptor.

    Example:
        >>> import advgame
        >>> game = advgame.make("Ant-v5", preset="shift-deterministic")
        >>> ConstantAdversary((14.715, 1.0)).build(game.agent_info("dynamics_adversary")).act(None)
        array([-0.01998002,  0.        ], dtype=float32)

    """

    value: float | Sequence[float] = 0.0
    """The raw value (broadcast over the adversary's dimensions)."""

    def build(self, info: AgentInfo) -> Policy:
        """A constant policy sending the encoded value."""
        n = info.action_size
        return ConstantPolicy(info.encode(np.broadcast_to(np.asarray(self.value, float), (n,))))


class _Sinusoid:
    """Counts episodes (resets) and plays ``base + amplitude * sin(frequency * i + phase)``."""

    def __init__(
        self,
        info: AgentInfo,
        base: np.ndarray,
        amp: np.ndarray,
        freq: np.ndarray,
        phase: np.ndarray,
        start: int = 0,
    ) -> None:
        self.info, self.base, self.amp, self.freq, self.phase = info, base, amp, freq, phase
        self.episode = start - 1
        self._next: int | None = None
        self.action = info.encode(base)

    def set_episode_index(self, index: int) -> None:
        """Make the next `reset` start episode ``i = index`` instead of the next of its count.

        Evaluation tables call it (`advgame.core.episodes.reseed_policies`), so that each
        evaluation episode plays a declared episode of the schedule whatever policy object or
        worker plays it; later resets count on from there.
        """
        self._next = int(index)

    def episode_index(self) -> int:
        """The index ``i`` of the episode played now (``start - 1`` before the first reset)."""
        return self.episode

    def reset(self, seed: int | None = None) -> None:
        """Advance to the next episode index ``i`` (or the one `set_episode_index` gave)."""
        self.episode = self.episode + 1 if self._next is None else self._next
        self._next = None
        value = self.base + self.amp * np.sin(self.freq * self.episode + self.phase)
        self.action = self.info.encode(value)

    def act(self, observation: Any) -> np.ndarray:
        """The value of the current episode."""
        return self.action


@dataclass(frozen=True)
class SinusoidAdversary:
    """A shift that moves sinusoidally from episode to episode: ``base + A·sin(ω·i + φ)``.

    ``i`` counts the episodes the policy has played (its resets, from `start`). The
    appendix's Ant and Humanoid schedule is ``SinusoidAdversary(base=(14.715, 1.0),
    amplitude=(4.905, 0.2), frequency=0.5)`` on (gravity, wind). An evaluation table does not
    rely on the count: its episode ``k`` of a job (seed ``s``, episode ``e`` of ``E`` per seed:
    ``k = s·E + e``) plays ``i = k + 1`` (`advgame.evaluation.table.jobs.schedule_index`).

    Example:
        >>> import advgame
        >>> game = advgame.make("Ant-v5", preset="shift-sinusoid")
        >>> pol = SinusoidAdversary((14.715, 1.0), (4.905, 0.2), 0.5).build(
        ...     game.agent_info("dynamics_adversary"))
        >>> pol.reset(); pol.act(None)
        array([-0.01998002,  0.        ], dtype=float32)

    """

    base: float | Sequence[float] = 0.0
    """Centre value per dimension (raw units)."""
    amplitude: float | Sequence[float] = 0.0
    """Amplitude per dimension."""
    frequency: float | Sequence[float] = 0.5
    """Angular frequency per episode index."""
    phase: float | Sequence[float] = 0.0
    """Phase offset."""
    start: int = 0
    """The index ``i`` of the policy's first episode (OMPO's training loop counts from 1)."""

    def build(self, info: AgentInfo) -> Policy:
        """A policy that advances one episode per reset."""
        n = info.action_size
        vals = []
        for name in ("base", "amplitude", "frequency", "phase"):
            arr = np.asarray(getattr(self, name), dtype=np.float64)
            if arr.ndim > 1 or (arr.ndim == 1 and arr.size != n) or not np.isfinite(arr).all():
                raise ConfigError(f"SinusoidAdversary.{name} must be finite, scalar or {n} values.")
            vals.append(np.broadcast_to(arr, (n,)).copy())
        if type(self.start) is not int or self.start < 0:
            raise ConfigError(f"SinusoidAdversary.start must be an int >= 0, got {self.start!r}.")
        base, amp, freq, phase = vals
        return _Sinusoid(info, base, amp, freq, phase, start=self.start)
