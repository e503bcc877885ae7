"""The observation (state) disruptor: ``s~ = s + δ`` with δ in an ε-ball around the true state."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, cast

import numpy as np
from gymnasium import spaces

from advgame.core.disruptor import (
    AdditiveDisruptor,
    DisruptorSpec,
    as_budget,
    budget_array,
    resolve_targets,
)
from advgame.disruptors import dict_obs
from advgame.errors import BudgetError, ConfigError, UnknownNameError, did_you_mean

if TYPE_CHECKING:
    from advgame.core.task import TaskBase

__all__ = ["ObservationDisruptor", "ObservationRuntime", "moved"]

Bounds = tuple[np.ndarray, np.ndarray] | None


@dataclass(frozen=True, kw_only=True)
class ObservationDisruptor(DisruptorSpec):
    """Additive perturbation of what protagonists observe, inside an ε-ball.

    The adversary's action ``u`` lies in ``[-1, 1]^k`` (k = number of attacked dimensions summed
    over targets) and becomes ``δ = ε ⊙ u`` (L∞ ball) or ``δ = ε ⊙ u / max(1, ‖u‖₂)`` (L2 ball)
    in raw units, or ``δ = ε ⊙ σ ⊙ u`` in the protagonist's normalized space (ATLA), where σ is the
    running standard deviation set by `ObservationRuntime.set_scale`. The perturbed observation
    is clipped into the protagonist's observation space when that space is bounded.

    Dict observations (goal-conditioned robotics: ``observation``, ``achieved_goal``,
    ``desired_goal``; nested keys joined with ``/``) keep their structure: `keys` chooses the
    parts attacked, `eps` may give a budget per key (``{"desired_goal": 0.05, ...}``), and the
    adversary's action is the concatenation of the keys' blocks in the order of `keys` (default:
    every leaf in the Dict space's order); see `advgame.disruptors.dict_obs`. Only what the
    protagonist sees changes: the task keeps rewarding against its true goals.

    Example:
        >>> import advgame
        >>> game = advgame.make("Hopper-v5", disruptors=[ObservationDisruptor(eps=0.075)])
        >>> game.action_space("observation_adversary").shape
        (11,)

    """

    kind = "observation"
    budget_fields = ("eps",)
    eps: float | Sequence[float] | Mapping[str, float | Sequence[float]] = 0.1
    """Budget per attacked dimension (raw or normalized units); for Dict observations also a
    mapping from each attacked key to its budget (a scalar or one value per component)."""
    norm: Literal["linf", "l2"] = "linf"
    """Shape of the ball: per-dimension (``"linf"``) or Euclidean per target (``"l2"``)."""
    dims: Sequence[int] | None = None
    """Indices of the observation dimensions attacked (``None``: all)."""
    keys: Sequence[str] | None = None
    """Names of observation parts attacked: keys of a Dict observation (``"desired_goal"``,
    ``"achieved_goal/kettle"``; default with a per-key `eps` mapping: its keys), or, for tasks
    that flatten a dict observation and say where each key lies (``task.observation_keys``,
    e.g. robosuite's ``"object-state"``), those names; exclusive with `dims`."""
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
        if isinstance(self.eps, Mapping):
            self._check_key_budgets(self.eps)
        elif self.bounded:
            eps = budget_array(self.eps, "ObservationDisruptor.eps")
            as_budget(self.eps, eps.size if eps.ndim else 1, "ObservationDisruptor.eps")

    def _check_key_budgets(self, eps: Mapping[str, Any]) -> None:
        """A per-key budget: bounded, and naming exactly the attacked keys when both are given."""
        for key in eps:
            if not isinstance(key, str):
                raise BudgetError(f"A per-key eps mapping has string keys, got {key!r}.")
        if not self.bounded or self.dims is not None or self.space != "raw":
            raise ConfigError(
                "A per-key eps mapping needs bounded=True, raw units and no dims, got "
                f"bounded={self.bounded!r}, space={self.space!r}, dims={self.dims!r}."
            )
        if self.keys is not None and set(eps) != set(self.keys):
            raise BudgetError(
                f"eps gives budgets for {sorted(eps)} but keys={list(self.keys)!r}; give one "
                "budget per attacked key (or leave keys out: the mapping's keys are attacked)."
            )
        for key, value in eps.items():
            arr = budget_array(value, f"ObservationDisruptor.eps[{key!r}]")
            as_budget(value, arr.size if arr.ndim else 1, f"ObservationDisruptor.eps[{key!r}]")

    @property
    def dict_keys(self) -> Sequence[str] | None:
        """The keys of a Dict observation attacked (None: every leaf)."""
        if self.keys is None and isinstance(self.eps, Mapping):
            return list(self.eps)
        return self.keys

    def build(self, task: TaskBase) -> ObservationRuntime:
        """Bind to `task`: check dims (or Dict keys) against each target's observation space."""
        targets = resolve_targets(task, self.targets)
        dims: dict[str, np.ndarray] = {}
        plans: dict[str, list[dict_obs.Leaf]] = {}
        for t in targets:
            space = task.observation_spaces[t]
            if isinstance(space, spaces.Dict):
                plans[t] = self._dict_plan(t, space)
                dims[t] = np.arange(plans[t][-1].block.stop)
                continue
            if isinstance(self.eps, Mapping):
                raise ConfigError(
                    f"A per-key eps mapping needs a Dict observation; {t!r} observes {space}."
                )
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
        return ObservationRuntime(self, task, targets, dims, plans)

    def _dict_plan(self, target: str, space: spaces.Dict) -> list[dict_obs.Leaf]:
        """The leaves of `target`'s Dict observation this disruptor perturbs."""
        if self.dims is not None or self.space != "raw":
            raise ConfigError(
                f"{target!r} observes a Dict; choose its parts with keys=[...] (not dims) and "
                f"raw units, got dims={self.dims!r}, space={self.space!r}."
            )
        plan = dict_obs.layout(space, self.dict_keys)
        if not plan:
            raise ConfigError(f"keys={self.keys!r} selects nothing of {target!r}'s observation.")
        return plan


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
        plans: dict[str, list[dict_obs.Leaf]] | None = None,
    ) -> None:
        self.targets = targets
        self.dims = dims
        self.plans = plans or {}
        """Per target with a Dict observation: the leaves perturbed, in action order."""
        # build() checked that every other target observes a Box
        self.spaces: dict[str, spaces.Box] = {
            t: cast(spaces.Box, task.observation_spaces[t]) for t in targets if t not in self.plans
        }
        self.full = {t: dims[t].size == int(np.prod(s.shape)) for t, s in self.spaces.items()}
        self.eps = {t: self._budget(spec, t) for t in targets}
        self.scale = {t: np.ones(dims[t].size) for t in targets}
        self.clip_obs = {
            t: bool(np.isfinite(s.low).any() or np.isfinite(s.high).any())
            for t, s in self.spaces.items()
        }
        self.timing = spec.timing
        sizes: list[int] = []
        for t in targets:  # the L2 ball is per target, and per key of a Dict observation
            sizes += dict_obs.key_blocks(self.plans[t]) if t in self.plans else [dims[t].size]
        super().__init__(spec, self._unit(), bounded=spec.bounded, norm=spec.norm, blocks=sizes)
        self._plan = self._blocks()
        t0, block0, full0, space0, bounds0 = self._plan[0]
        self._lone: tuple[str, spaces.Box, Bounds] | None = (
            (t0, space0, bounds0)
            if len(self._plan) == 1 and block0 is None and full0 and space0 is not None
            else None
        )
        """(target, space, bounds) when `observation` has one whole Box target, else None."""
        self._flat = all(  # every target a whole 1-D Box: `observation_rows` stacks them
            space is not None and full and len(space.shape) == 1
            for _, _, full, space, _ in self._plan
        )

    def _budget(self, spec: ObservationDisruptor, target: str) -> np.ndarray:
        if not spec.bounded:
            return np.ones(self.dims[target].size)
        if target in self.plans:
            return dict_obs.budget(self.plans[target], spec.eps)
        return as_budget(spec.eps, self.dims[target].size, "ObservationDisruptor.eps")  # type: ignore[arg-type]

    def _unit(self) -> np.ndarray:
        return np.concatenate([self.eps[t] * self.scale[t] for t in self.targets])

    def set_scale(self, target: str, std: Any) -> None:
        """Set the normalizer's standard deviation for `target` (normalized-space budgets only).

        Call it again whenever the protagonist's normalizer changes; a frozen normalizer keeps the
        budget fixed during an adversary phase.
        """
        if self.spec.space != "normalized" or target in self.plans:  # type: ignore[attr-defined]
            raise ConfigError(
                "set_scale applies only to ObservationDisruptor(space='normalized') on a Box "
                "observation."
            )
        std = np.asarray(std, dtype=np.float64).reshape(-1)
        n = int(np.prod(self.spaces[target].shape))
        if std.shape != (n,) or not np.all(np.isfinite(std)) or np.any(std <= 0):
            raise BudgetError(
                f"set_scale needs {n} finite positive stds for {target!r}, got shape {std.shape} "
                f"with min {std.min() if std.size else None}."
            )
        self.scale[target] = std[self.dims[target]]
        self.unit = self._unit()

    def _blocks(self) -> list[tuple[str, slice | None, bool, spaces.Box | None, Bounds]]:
        """Per target: its block of δ (``None``: all), whether it is whole, its space, its bounds.

        A target with a Dict observation has space None (its plan says where δ goes).

        Bounds (``None`` when unbounded) are kept in float64, the dtype of the perturbed
        observation: clipping against float32 bounds would convert them (exactly) every call.
        """
        out: list[tuple[str, slice | None, bool, spaces.Box | None, Bounds]] = []
        i = 0
        whole = len(self.targets) == 1
        for t in self.targets:
            n, box = self.dims[t].size, self.spaces.get(t)
            block = None if whole else slice(i, i + n)
            if box is None:
                out.append((t, block, True, None, None))
                i += n
                continue
            space = box
            bounds = (space.low.astype(np.float64), space.high.astype(np.float64))
            out.append((t, block, self.full[t], space, bounds if self.clip_obs[t] else None))
            i += n
        return out

    def observation(self, observations: dict[str, Any], u: np.ndarray) -> None:
        """Add δ to each target's observation, clipped into its observation space (`moved`)."""
        if self._lone is not None:  # one whole 1-D Box target: the loop below, its one case
            target, box, box_bounds = self._lone
            obs = observations[target]
            if obs.ndim == 1:
                observations[target] = moved(obs, self.perturbation(u), None, box, box_bounds)
                return
        delta = self.perturbation(u)
        for t, block, full, space, bounds in self._plan:
            d = delta if block is None else delta[block]
            obs = observations[t]
            if space is None:  # a Dict observation: a new dict, the true one untouched
                observations[t] = dict_obs.perturb(obs, self.plans[t], d)
                continue
            whole = full and len(space.shape) == 1
            observations[t] = moved(obs, d, None if whole else self.dims[t], space, bounds)

    def observation_rows(
        self, peers: Sequence[Any], observations: Sequence[dict[str, Any]], u: Any
    ) -> None:
        """`observation` over N alike games at once: their rows stacked, then `observation_array`.

        When the peers' budgets differ (e.g. another normalizer std) or an observation is not
        a whole flat Box, each peer perturbs its own row.
        """
        if not (self._flat and isinstance(u, np.ndarray) and self._same_unit(peers)):
            super().observation_rows(peers, observations, u)
            return
        stacked = {t: np.array([obs[t] for obs in observations]) for t in self.targets}
        self.observation_array(stacked, u)  # np.array of the rows: np.stack's value, faster
        for t, rows in stacked.items():
            for obs, row in zip(observations, rows, strict=True):
                obs[t] = row

    def observation_array(self, observations: dict[str, np.ndarray], u: np.ndarray) -> None:
        """`observation` of every row at once: ``[M, dims]`` sums and clips per target (`moved`).

        Each row gets exactly the single copy's value; Dict observations go row by row.
        """
        if self.plans or any(space is None or len(space.shape) != 1 for *_, space, _ in self._plan):
            super().observation_array(observations, u)
            return
        delta = self.perturbation(u)
        for t, block, full, space, bounds in self._plan:
            assert space is not None  # no Dict plans (checked above)
            d = delta if block is None else delta[:, block]
            dims = None if full else self.dims[t]
            observations[t] = moved(observations[t], d, dims, space, bounds)


def moved(
    obs: np.ndarray, d: np.ndarray, dims: np.ndarray | None, space: spaces.Box, bounds: Bounds
) -> np.ndarray:
    """A Box observation plus its δ, clipped into `space` (its `bounds`) and cast to its dtype.

    The one implementation of the perturbation that the single game, the lockstep rows and the
    array game all apply: `obs` is one observation (shape ``space.shape``) or rows of them
    (``[M, *space.shape]``), `d` the matching δ (``[k]`` or ``[M, k]``) for the flat indices
    `dims` (``None``: a 1-D space's every component, in order). The sum is float64, as the
    float64 δ makes it.
    """
    if dims is None:
        return _into(obs + d, space, bounds)
    lead = obs.shape[: obs.ndim - len(space.shape)]  # () for one observation, (M,) for rows
    new = np.array(obs, dtype=np.float64).reshape(*lead, -1)
    new[..., dims] += d
    return _into(new.reshape(*lead, *space.shape), space, bounds)


def _into(new: np.ndarray, space: spaces.Box, bounds: Bounds) -> np.ndarray:
    """Perturbed observations (float64) clipped into `space` (its `bounds`) and cast to its dtype."""
    if bounds is not None:
        new = new.clip(*bounds)  # = np.clip(new, space.low, space.high), less dispatch
    if new.dtype != space.dtype:
        new = (np.rint(new) if np.issubdtype(space.dtype, np.integer) else new).astype(space.dtype)
    return new
