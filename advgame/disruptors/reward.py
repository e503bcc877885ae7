"""The reward and cost disruptor: bounded changes to what the learner *observes*.

The true reward and cost are untouched: they stay in ``infos[agent]["true_reward"]`` and
``infos[agent]["true_cost"]``, the adversaries are paid on them, and evaluation reports them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from advgame.core.disruptor import AdditiveDisruptor, DisruptorSpec, as_budget, resolve_targets
from advgame.errors import ConfigError

if TYPE_CHECKING:
    from advgame.core.task import TaskBase

__all__ = ["RewardDisruptor", "RewardRuntime"]


@dataclass(frozen=True, kw_only=True)
class RewardDisruptor(DisruptorSpec):
    """Additive perturbation ``r~ = r + ε·u``, ``u ∈ [-1, 1]``, of the observed reward (or cost).

    Example:
        >>> import advgame
        >>> game = advgame.make("Hopper-v5", disruptors=[RewardDisruptor(eps=0.5)])
        >>> game.action_space("reward_adversary").shape
        (1,)

    """

    kind = "reward"
    budget_fields = ("eps",)
    eps: float = 0.1
    """Largest change of the observed reward (or cost) per step."""
    signal: Literal["reward", "cost"] = "reward"
    """Which learning signal is perturbed."""
    targets: Sequence[str] | None = None
    """Protagonists whose observed signal is perturbed (``None``: all)."""
    bounded: bool = True
    """``False``: the paper's unbounded random mode (the action is the raw change)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.signal not in ("reward", "cost"):
            raise ConfigError(f"signal must be 'reward' or 'cost', got {self.signal!r}.")
        if self.bounded:
            as_budget(self.eps, 1, "RewardDisruptor.eps")

    @property
    def agent(self) -> str:
        """``"reward_adversary"`` or ``"cost_adversary"`` unless named."""
        return self.name or f"{self.signal}_adversary"

    def build(self, task: TaskBase) -> RewardRuntime:
        """Bind to `task` (one action dimension per target)."""
        return RewardRuntime(self, resolve_targets(task, self.targets))


class RewardRuntime(AdditiveDisruptor):
    """`RewardDisruptor` bound to a task."""

    hook = "reward"

    def __init__(self, spec: RewardDisruptor, targets: tuple[str, ...]) -> None:
        self.targets = targets
        self.signal = spec.signal
        eps = float(spec.eps) if spec.bounded else 1.0
        super().__init__(spec, np.full(len(targets), eps), bounded=spec.bounded)

    def reward(self, rewards: dict[str, float], costs: dict[str, float], u: np.ndarray) -> None:
        """Add the change to each target's observed reward (or cost)."""
        signal = rewards if self.signal == "reward" else costs
        delta = self.perturbation(u)
        for i, t in enumerate(self.targets):
            signal[t] = signal[t] + float(delta[i])

    def reward_array(
        self, rewards: dict[str, np.ndarray], costs: dict[str, np.ndarray], u: np.ndarray
    ) -> None:
        """`reward` of every row at once: ``[M]`` float64 sums, as the single copy's float sums."""
        signal = rewards if self.signal == "reward" else costs
        delta = self.perturbation(u)
        for i, t in enumerate(self.targets):
            signal[t] = signal[t] + delta[:, i]
