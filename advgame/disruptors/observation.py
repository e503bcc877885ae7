"""The observation (state) disruptor: ``s~ = s + δ`` with δ in an ε-ball around the true state."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, cast

import numpy as np
from gymnasium import spaces

from advgame.disruptors.base import AdditiveDisruptor, DisruptorSpec, as_budget, resolve_targets
from advgame.errors import BudgetError, ConfigError, UnknownNameError, did_you_mean

if TYPE_CHECKING:
    from advgame.core.task import TaskBase

__all__ = ["ObservationDisruptor", "ObservationRuntime"]

Bounds = tuple[np.ndarray, np.ndarray] | None


@dataclass(frozen=True, kw_only=True)
class ObservationDisruptor(DisruptorSpec):
    """Additive perturbation of what protagonists observe, inside an ε-ball.

    The adversary's action ``u`` lies in ``[-1, 1]^k`` (k = number of attacked dimensions summed
    over targets) and becomes ``δ = ε ⊙ u`` (L∞ ball) or ``δ = ε ⊙ u / max(1, ‖u‖₂)`` (L2 ball)
    in raw units, or ``δ = ε ⊙ σ ⊙ u`` in the protagonist's normalized space (ATLA), where σ is the
    running standard deviation set by `ObservationRuntime.set_scale`. The perturbed observation
    is clipped into the protagonist's observation space when that space is bounded.

    Example:
        >>> import advgame
        >>> game = advgame.make("Hopper-v5", disruptors=[ObservationDisruptor(eps=0.075)])
        >>> game.action_space("observation_adversary").shape
        (11,)

    """

    kind = "observation"
    eps: float | Sequence[float] = 0.1
    """Budget per attacked dimension (raw or normalized units)."""
    norm: Literal["linf", "l2"] = "linf"
    """Shape of the ball: per-dimension (``"linf"``) or Euclidean per target (``"l2"``)."""
    dims: Sequence[int] | None = None
    """Indices of the observation dimensions attacked (``None``: all)."""
    keys: Sequence[str] | None = None
    """Names of observation parts attacked, for tasks that flatten a dict observation and say
    where each key lies (``task.observation_keys``, e.g. robosuite's ``"object-state"``);
    exclusive with `dims`."""
    targets: Sequence[str] | None = None
    """Protagonists whose observations are perturbed (``None``: all; a subset is a partial attack)."""
    space: Literal["raw", "normalized"] = "raw"
    """Units of ε: raw observation units or the protagonist's normalized units (ATLA)."""
    timing: Literal["sense", "stale"] = "sense"
    """``"sense"``: the adversary sees ``s_t`` and moves before the protagonist acts on ``s_t + δ_t``
    (the faithful order). ``"stale"``: it moves with the protagonist and its δ lands on the next
    observation — a weaker, one-step-stale game, offered only as this named option."""
    bounded: bool = True
    """``False``: the paper's unbounded random mode; the action is the raw δ and ε is unused."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.norm not in ("linf", "l2"):
            raise ConfigError(f"norm must be 'linf' or 'l2', got {self.norm!r}.")
        if self.space not in ("raw", "normalized"):
            raise ConfigError(f"space must be 'raw' or 'normalized', got {self.space!r}.")
        if self.timing not in ("sense", "stale"):
            raise ConfigError(f"timing must be 'sense' or 'stale', got {self.timing!r}.")
        if self.keys is not None and (self.dims is not None or isinstance(self.keys, str)):
            raise ConfigError(
                f"keys must be a list of names and exclusive with dims, got keys={self.keys!r}, "
                f"dims={self.dims!r}."
            )
        if self.bounded:
            eps = np.asarray(self.eps, dtype=np.float64)
            as_budget(self.eps, eps.size if eps.ndim else 1, "ObservationDisruptor.eps")

    def build(self, task: TaskBase) -> ObservationRuntime:
        """Bind to `task`: check dims against each target's observation space."""
        targets = resolve_targets(task, self.targets)
        dims: dict[str, np.ndarray] = {}
        for t in targets:
            space = task.observation_spaces[t]
            if not isinstance(space, spaces.Box):
                raise ConfigError(
                    f"Observation of {t!r} is {space}; only Box observations can be perturbed."
                )
            n = int(np.prod(space.shape))
            if self.keys is not None:
                idx = _key_dims(task, self.keys)
            else:
                idx = np.arange(n) if self.dims is None else np.asarray(self.dims, dtype=np.int64)
            if idx.ndim != 1 or idx.size == 0 or idx.min() < 0 or idx.max() >= n:
                raise BudgetError(
                    f"dims must be indices in [0, {n}) of {t!r}'s flattened observation, got {self.dims!r}."
                )
            dims[t] = idx
        return ObservationRuntime(self, task, targets, dims)


def _key_dims(task: TaskBase, keys: Sequence[str]) -> np.ndarray:
    """The flattened indices of observation `keys` (the task's ``observation_keys`` slices)."""
    table = getattr(task, "observation_keys", None)
    if not table:
        raise ConfigError(
            f"{type(task).__name__} has no named observation keys; use dims=[...] instead of keys."
        )
    out = []
    for k in keys:
        if k not in table:
            raise UnknownNameError(
                f"No observation key {k!r}.{did_you_mean(k, table)} Keys: {list(table)}."
            )
        out.append(np.arange(table[k].start, table[k].stop))
    return np.concatenate(out) if out else np.zeros(0, dtype=np.int64)


class ObservationRuntime(AdditiveDisruptor):
    """`ObservationDisruptor` bound to a task."""

    hook = "observation"

    def __init__(
        self,
        spec: ObservationDisruptor,
        task: TaskBase,
        targets: tuple[str, ...],
        dims: dict[str, np.ndarray],
    ) -> None:
        self.targets = targets
        self.dims = dims
        # build() checked that every target observes a Box
        self.spaces: dict[str, spaces.Box] = {
            t: cast(spaces.Box, task.observation_spaces[t]) for t in targets
        }
        self.full = {t: dims[t].size == int(np.prod(self.spaces[t].shape)) for t in targets}
        self.eps = {
            t: as_budget(spec.eps, dims[t].size, "ObservationDisruptor.eps")
            if spec.bounded
            else np.ones(dims[t].size)
            for t in targets
        }
        self.scale = {t: np.ones(dims[t].size) for t in targets}
        self.clip_obs = {
            t: bool(np.isfinite(s.low).any() or np.isfinite(s.high).any())
            for t, s in self.spaces.items()
        }
        self.timing = spec.timing
        sizes = [dims[t].size for t in targets]
        super().__init__(spec, self._unit(), bounded=spec.bounded, norm=spec.norm, blocks=sizes)
        self._plan = self._blocks()

    def _unit(self) -> np.ndarray:
        return np.concatenate([self.eps[t] * self.scale[t] for t in self.targets])

    def set_scale(self, target: str, std: Any) -> None:
        """Set the normalizer's standard deviation for `target` (normalized-space budgets only).

        Call it again whenever the protagonist's normalizer changes; a frozen normalizer keeps the
        budget fixed during an adversary phase.
        """
        if self.spec.space != "normalized":  # type: ignore[attr-defined]
            raise ConfigError("set_scale applies only to ObservationDisruptor(space='normalized').")
        std = np.asarray(std, dtype=np.float64).reshape(-1)
        n = int(np.prod(self.spaces[target].shape))
        if std.shape != (n,) or not np.all(np.isfinite(std)) or np.any(std <= 0):
            raise BudgetError(
                f"set_scale needs {n} finite positive stds for {target!r}, got shape {std.shape} "
                f"with min {std.min() if std.size else None}."
            )
        self.scale[target] = std[self.dims[target]]
        self.unit = self._unit()

    def _blocks(self) -> list[tuple[str, slice | None, bool, spaces.Box, Bounds]]:
        """Per target: its block of δ (``None``: all), whether it is whole, its space, its bounds.

        Bounds (``None`` when unbounded) are kept in float64, the dtype of the perturbed
        observation: clipping against float32 bounds would convert them (exactly) every call.
        """
        out, i = [], 0
        whole = len(self.targets) == 1
        for t in self.targets:
            n, space = self.dims[t].size, self.spaces[t]
            block = None if whole else slice(i, i + n)
            bounds = (space.low.astype(np.float64), space.high.astype(np.float64))
            out.append((t, block, self.full[t], space, bounds if self.clip_obs[t] else None))
            i += n
        return out

    def observation(self, observations: dict[str, Any], u: np.ndarray) -> None:
        """Add δ to each target's observation, clipped into its observation space."""
        delta = self.perturbation(u)
        for t, block, full, space, bounds in self._plan:
            d = delta if block is None else delta[block]
            obs = observations[t]
            if full and obs.ndim == 1:
                new = obs + d
            else:
                new = np.array(obs, dtype=np.float64).reshape(-1)
                new[self.dims[t]] += d
                new = new.reshape(space.shape)
            if bounds is not None:
                new = new.clip(*bounds)  # = np.clip(new, space.low, space.high), less dispatch
            if new.dtype != space.dtype:
                new = (np.rint(new) if np.issubdtype(space.dtype, np.integer) else new).astype(
                    space.dtype
                )
            observations[t] = new
