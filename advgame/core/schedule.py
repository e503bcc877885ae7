"""When a disruptor acts: every step, every N steps, once per episode, with probability p, in a window.

A `Schedule` also names the *phase* it belongs to: ``"train"``, ``"eval"`` or ``"both"`` (the paper's
in-training setting disrupts in both; its post-training setting only in ``"eval"``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from advgame.core.fields import check_fields
from advgame.errors import ConfigError

__all__ = ["PHASES", "Phase", "Schedule"]

Phase = Literal["train", "eval", "both"]
PHASES: tuple[str, ...] = ("train", "eval", "both")


@dataclass(frozen=True)
class Schedule:
    """When a disruptor's adversary acts within an episode, and in which phase.

    A step ``t`` (0-based, counting protagonist steps of the current episode) is *active* when
    ``start <= t < stop``, ``(t - start) % every == 0``, ``t == start`` if `once_per_episode`, and a
    Bernoulli(`probability`) draw from the game's seeded generator succeeds. On inactive steps the
    disruptor is the identity, unless `hold` keeps its last perturbation in force. Environment
    parameters (dynamics) always stay as last set until the episode ends.

    Example:
        >>> Schedule.every_n(100).is_active(200, "train", None)
        True
        >>> Schedule(phase="eval").is_active(0, "train", None)
        False

    """

    every: int = 1
    """Act on every `every`-th step of the window (the paper's "100F" is ``every=100``)."""
    probability: float = 1.0
    """Probability that an otherwise active step is attacked (drawn from the game's generator)."""
    start: int = 0
    """First step of the window in which the disruptor may act."""
    stop: int | None = None
    """First step after the window (``None``: until the episode ends)."""
    once_per_episode: bool = False
    """Act only on the first step of the window, once per episode."""
    phase: Phase = "both"
    """``"train"``, ``"eval"`` or ``"both"``: the game phases in which the disruptor is live."""
    hold: bool = False
    """Keep the last perturbation in force on inactive steps instead of reverting to the identity."""
    persist: bool = False
    """Environment disruptors only: keep a shift across resets instead of restoring nominal values."""

    def __post_init__(self) -> None:
        check_fields(self)
        if self.every < 1:
            raise ConfigError(f"Schedule.every must be an int >= 1, got {self.every!r}.")
        if not (0.0 <= float(self.probability) <= 1.0):
            raise ConfigError(f"Schedule.probability must be in [0, 1], got {self.probability!r}.")
        if not isinstance(self.start, int) or self.start < 0:
            raise ConfigError(f"Schedule.start must be an int >= 0, got {self.start!r}.")
        if self.stop is not None and (not isinstance(self.stop, int) or self.stop <= self.start):
            raise ConfigError(
                f"Schedule.stop must be None or an int > start={self.start}, got {self.stop!r}."
            )
        if self.phase not in PHASES:
            raise ConfigError(f"Schedule.phase must be one of {PHASES}, got {self.phase!r}.")

    @classmethod
    def every_step(cls, phase: Phase = "both") -> Schedule:
        """Act on every step (the default)."""
        return cls(phase=phase)

    @classmethod
    def every_n(cls, n: int, phase: Phase = "both") -> Schedule:
        """Act every `n` steps (the paper's ``nF`` frequency attacks)."""
        return cls(every=n, phase=phase)

    @classmethod
    def per_episode(cls, phase: Phase = "both", persist: bool = False) -> Schedule:
        """Act once, on the first step of each episode, and hold it for the whole episode."""
        return cls(once_per_episode=True, hold=True, phase=phase, persist=persist)

    @classmethod
    def with_probability(cls, p: float, phase: Phase = "both") -> Schedule:
        """Act on each step with probability `p`."""
        return cls(probability=p, phase=phase)

    @classmethod
    def window(cls, start: int, stop: int | None, phase: Phase = "both") -> Schedule:
        """Act on every step in ``[start, stop)``."""
        return cls(start=start, stop=stop, phase=phase)

    def in_phase(self, phase: str) -> bool:
        """Whether the disruptor is live at all in game phase `phase` (``"train"`` or ``"eval"``)."""
        return self.phase == "both" or self.phase == phase

    def exhausted(self, t: int) -> bool:
        """Whether no step ``>= t`` of this episode can be active (the window has closed)."""
        if self.once_per_episode and t > self.start:
            return True
        return self.stop is not None and t >= self.stop

    def constant(self, phase: str) -> bool | None:
        """`is_active` of every step in `phase` when it is the same for all and draws nothing.

        ``False`` outside the schedule's phase, ``True`` for an every-step schedule, else
        ``None`` (activity depends on the step or on a random draw). The game uses it to skip
        evaluating constant schedules step by step.

        Example:
            >>> Schedule().constant("train"), Schedule.every_n(2).constant("train")
            (True, None)

        """
        if not self.in_phase(phase):
            return False
        always = self.every == 1 and self.start == 0 and self.stop is None
        if always and not self.once_per_episode and self.probability >= 1.0:
            return True
        return None

    def is_active(self, t: int, phase: str, rng: np.random.Generator | None) -> bool:
        """Whether step `t` is attacked; draws from `rng` only when `probability` < 1."""
        if not self.in_phase(phase) or t < self.start:
            return False
        if self.stop is not None and t >= self.stop:
            return False
        if self.once_per_episode:
            if t != self.start:
                return False
        elif (t - self.start) % self.every:
            return False
        if self.probability < 1.0:
            if rng is None:
                raise ConfigError("A probabilistic Schedule needs a random generator.")
            return bool(rng.random() < self.probability)
        return True

    def active_rows(
        self, t: np.ndarray, phase: str, rngs: Sequence[np.random.Generator], live: np.ndarray
    ) -> np.ndarray:
        """`is_active` of N copies at once: row ``i`` at step ``t[i]`` (``[N]`` bool).

        The same rules over arrays (`advgame.core.array_game.ArrayGame`); the probability is
        drawn from ``rngs[i]`` for each live copy that passes the other rules, in row order, as
        each copy's own game would draw it. Copies not `live` are inactive and draw nothing.
        """
        if not self.in_phase(phase):
            return np.zeros(len(t), np.bool_)
        on = live & (t >= self.start)
        if self.stop is not None:
            on &= t < self.stop
        if self.once_per_episode:
            on &= t == self.start
        else:
            on &= (t - self.start) % self.every == 0
        if self.probability < 1.0:
            for i in np.flatnonzero(on):
                on[i] = rngs[i].random() < self.probability
        return on
