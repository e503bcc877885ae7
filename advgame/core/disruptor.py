"""The disruptor contract: one hook, one bounded adversary action space, one budget.

A disruptor comes in two halves, as Gymnasium wrappers do with their constructor arguments:

* a *spec* (`DisruptorSpec`), a frozen, validated dataclass that says what is perturbed, the
  budget and the `Schedule`; it is what configs, presets and files hold;
* a *runtime* (`Disruptor`), built from the spec against one task base by `DisruptorSpec.build`.
  It owns the adversary's `Box` action space and overrides exactly one hook: `observation`,
  `action`, `reward` or `environment`.

Every adversary action passes through `Disruptor.decode` first: wrong shapes and non-finite
values raise `ActionError`; values outside the normalized box are clipped and counted, so nothing
an adversary sends can leave the budget.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np
from gymnasium import spaces

from advgame.core.array_hooks import ArrayHooks
from advgame.core.checks import SMALL, all_finite, clip_ufunc, in_unit_box
from advgame.core.fields import check_fields
from advgame.core.schedule import Schedule
from advgame.errors import ActionError, BudgetError, UnknownNameError, did_you_mean

if TYPE_CHECKING:
    from advgame.core.task import MujocoSim, TaskBase

__all__ = [
    "SMALL",
    "AdditiveDisruptor",
    "Disruptor",
    "DisruptorSpec",
    "Hook",
    "all_finite",
    "as_budget",
    "budget_array",
    "clip_ufunc",
    "in_unit_box",
    "resolve_targets",
]

Hook = Literal["observation", "action", "reward", "environment"]


def budget_array(value: Any, what: str) -> np.ndarray:
    """`value` (a number or a list of numbers) as a float array.

    Raises:
        BudgetError: if it is not numeric (a string, None, a dict, a bool, a ragged list).

    """
    try:
        if isinstance(value, (bool, str, bytes, Mapping)) or value is None:
            raise TypeError
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise BudgetError(
            f"{what} must be a number or a list of numbers, got {value!r} "
            f"({type(value).__name__}); e.g. 0.1 or [0.1, 0.2]."
        ) from None


def as_budget(value: float | Sequence[float], size: int, what: str) -> np.ndarray:
    """Validate a budget (scalar or per-dimension) and broadcast it to `size` entries.

    Raises:
        BudgetError: if it is negative, non-finite or of the wrong length.

    """
    arr = budget_array(value, what)
    if arr.ndim > 1 or (arr.ndim == 1 and arr.shape[0] != size):
        raise BudgetError(
            f"{what} must be a scalar or a sequence of {size} values, got shape {arr.shape}."
        )
    if not np.all(np.isfinite(arr)):
        raise BudgetError(
            f"{what} must be finite, got {value!r}. For the paper's unbounded random mode "
            "set bounded=False instead of an infinite budget."
        )
    if np.any(arr < 0):
        raise BudgetError(f"{what} must be >= 0, got {value!r}.")
    return np.broadcast_to(arr, (size,)).astype(np.float64)


def resolve_targets(task: TaskBase, targets: Sequence[str] | None) -> tuple[str, ...]:
    """The protagonists a disruptor acts on: all of them if `targets` is None."""
    if targets is None:
        return task.protagonists
    if isinstance(targets, str):
        targets = (targets,)
    out = tuple(targets)
    for t in out:
        if t not in task.protagonists:
            raise UnknownNameError(
                f"Unknown target protagonist {t!r}.{did_you_mean(t, task.protagonists)} "
                f"Protagonists of this task: {list(task.protagonists)}."
            )
    if not out or len(set(out)) != len(out):
        raise BudgetError(f"targets must be non-empty and unique, got {targets!r}.")
    return out


@dataclass(frozen=True, kw_only=True)
class DisruptorSpec(abc.ABC):
    """The configuration of one disruptor: what it perturbs, its budget and its schedule.

    Subclasses add their budget fields and implement `build`.
    """

    schedule: Schedule = field(default_factory=Schedule)
    """When the disruptor acts, and in which phase."""
    name: str | None = None
    """The adversary agent id; default ``"<kind>_adversary"``."""

    kind: ClassVar[str] = ""
    """Registry name of the disruptor kind (``"observation"``, ``"action"``, ...)."""
    budget_fields: ClassVar[tuple[str, ...]] = ()
    """Budget fields, checked by `as_budget` (with their shapes) rather than by type."""

    def __post_init__(self) -> None:
        check_fields(self, skip=self.budget_fields)

    @property
    def agent(self) -> str:
        """The adversary agent id this disruptor gives the game."""
        return self.name or f"{self.kind}_adversary"

    @abc.abstractmethod
    def build(self, task: TaskBase) -> Disruptor:
        """Bind the spec to `task`, checking names and shapes against it."""


class Disruptor(ArrayHooks, abc.ABC):
    """A disruptor bound to a task: the adversary's action space and one hook.

    Args:
        spec: the configuration it was built from.
        size: the adversary's action dimension.
        bounded: ``True`` for a normalized ``[-1, 1]^size`` action space mapped into the budget;
            ``False`` for the paper's unbounded random mode, where the action is the raw
            perturbation.
        norm: ``"linf"`` clips each component; ``"l2"`` also projects each target's block onto
            the unit ball (`blocks` gives the block sizes).

    """

    hook: ClassVar[Hook]
    """Which step of the interaction the disruptor perturbs."""

    def __init__(
        self,
        spec: DisruptorSpec,
        size: int,
        bounded: bool = True,
        norm: str = "linf",
        blocks: Sequence[int] | None = None,
    ) -> None:
        self.spec = spec
        self.agent = spec.agent
        self.schedule = spec.schedule
        self.bounded = bounded
        self.norm = norm
        self.blocks = tuple(blocks) if blocks is not None else (size,)
        self._box = bounded and norm == "linf"  # an action inside [-1, 1] is decoded as it is
        bound = 1.0 if bounded else np.inf
        self.action_space = spaces.Box(-bound, bound, shape=(size,), dtype=np.float32)
        self.shape = (size,)
        self.clip_count = 0
        """Adversary action components clipped (or L2 projections) since the last reset."""

    @property
    def noop_action(self) -> np.ndarray:
        """The adversary action that leaves the task unchanged (zeros for additive perturbations)."""
        return np.zeros(self.shape, dtype=np.float32)

    def decode(self, action: Any) -> tuple[np.ndarray, int]:
        """Validate an adversary action; return it clipped into the budget and the clip count.

        Raises:
            ActionError: wrong shape, or NaN/inf in the action.

        """
        try:
            if type(action) is np.ndarray:  # astype: the same result as asarray, less dispatch
                u = action.astype(np.float64, copy=False)
            else:
                u = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ActionError(
                f"Action for {self.agent!r} is not numeric: {action!r}; expected {self.action_space}."
            ) from None
        if u.shape != self.shape:
            raise ActionError(
                f"Action for {self.agent!r} has shape {u.shape}; expected {self.shape} "
                f"(its action space is {self.action_space})."
            )
        # the common case: finite and inside the box, nothing to clip (`_passes`, inlined for
        # one action: it runs on every move of every game)
        if (self._box and in_unit_box(u)) if self.bounded else all_finite(u):
            return u, 0
        return self._decode_slow(u)

    def decode_rows(
        self, peers: Sequence[Disruptor], actions: Any
    ) -> tuple[np.ndarray | list[np.ndarray], list[int]]:
        """``peers[i].decode(actions[i])`` for every ``i``, checked once over the batch.

        `peers` are this disruptor's twins in N alike games (built from equal specs against
        equal tasks; `advgame.core.lockstep`), this one among them. When the stacked actions
        ``[N, size]`` are finite and inside the box (the common case) one test covers all
        rows and they are returned as they are; otherwise each peer decodes its own row, so
        errors, clips and each peer's ``clip_count`` are exactly those of one-by-one decoding.
        Returns the decoded rows (a ``[N, size]`` array or a list) and the clip counts.
        """
        n = len(peers)
        try:
            u = np.asarray(actions, dtype=np.float64)
        except (TypeError, ValueError):  # ragged or not numeric: the rows' own errors say why
            u = None
        if u is not None and u.shape == (n, *self.shape) and self._passes(u):
            return u, [0] * n
        decoded = [p.decode(a) for p, a in zip(peers, actions, strict=True)]
        return [d[0] for d in decoded], [d[1] for d in decoded]

    def _passes(self, u: np.ndarray) -> bool:
        """One cheap test that `u` (one action, or a batch of them) decodes to itself unclipped.

        ``False`` may be wrong: `_decode_slow` then settles it.
        """
        if not self.bounded:
            return all_finite(u)
        return self._box and in_unit_box(u)

    def _decode_slow(self, u: np.ndarray) -> tuple[np.ndarray, int]:
        """The precise checks of `_clip`, its clips counted in ``clip_count``."""
        u, clipped = self._clip(u)
        self.clip_count += clipped
        return u, clipped

    def _clip(self, u: np.ndarray) -> tuple[np.ndarray, int]:
        """Raise on NaN/inf, clip and count, project L2 blocks (``clip_count`` untouched)."""
        m = float(np.abs(u).max())  # one reduction: NaN and inf both fail `m <= bound`
        if not math.isfinite(m):
            raise ActionError(
                f"Action for {self.agent!r} contains NaN or inf: {u}. Adversary actions must "
                "be finite; out-of-range finite values are clipped into the budget."
            )
        if not self.bounded:
            return u, 0
        clipped = 0
        if m > 1.0:
            clipped = int(np.count_nonzero(np.abs(u) > 1.0))
            u = np.clip(u, -1.0, 1.0)
        if self.norm == "l2":
            u, projected = self._project_l2(u)
            clipped += projected
        return u, clipped

    def _project_l2(self, u: np.ndarray) -> tuple[np.ndarray, int]:
        out, projected, i = u.copy(), 0, 0
        for n in self.blocks:
            norm = float(np.linalg.norm(out[i : i + n]))
            if norm > 1.0:
                out[i : i + n] /= norm
                projected += 1
            i += n
        return out, projected

    def encode(self, value: Any) -> np.ndarray:
        """The adversary action that produces perturbation `value` (raw units), before clipping.

        Noise and schedule adversaries think in raw units (a state offset, a gravity value);
        this maps them into the adversary's action space. A batch ``(B, size)`` of values
        encodes row by row.
        """
        return np.asarray(value, dtype=np.float32).reshape(self._batch_shape(value))

    def _batch_shape(self, value: Any) -> tuple[int, ...]:
        return (-1, *self.shape) if np.ndim(value) == 2 else self.shape

    def reset(self) -> None:
        """Forget episode state (clip counts, held perturbations) at a game reset."""
        self.clip_count = 0

    # -- the hooks: each subclass overrides exactly one ----------------------------------------
    def observation(self, observations: dict[str, Any], u: np.ndarray) -> None:
        """Perturb protagonists' observations in place (observation disruptors)."""
        raise NotImplementedError(f"{type(self).__name__} is not an observation disruptor.")

    def action(self, actions: dict[str, Any], u: np.ndarray, rng: np.random.Generator) -> None:
        """Perturb protagonists' actions in place (action disruptors)."""
        raise NotImplementedError(f"{type(self).__name__} is not an action disruptor.")

    def reward(self, rewards: dict[str, float], costs: dict[str, float], u: np.ndarray) -> None:
        """Perturb the rewards or costs protagonists observe, in place (reward disruptors)."""
        raise NotImplementedError(f"{type(self).__name__} is not a reward disruptor.")

    def environment(self, sim: MujocoSim, u: np.ndarray | None) -> None:
        """Change the simulator before it steps; `u` is None on a step the schedule skips."""
        raise NotImplementedError(f"{type(self).__name__} is not an environment disruptor.")

    def restore(self, sim: MujocoSim) -> None:
        """Put every parameter this disruptor changed back to its nominal value."""

    # -- the hooks over N alike games (`advgame.core.lockstep`): row by row unless overridden --
    def observation_rows(
        self, peers: Sequence[Disruptor], observations: Sequence[dict[str, Any]], u: Any
    ) -> None:
        """`observation` of ``observations[i]`` with ``u[i]`` by ``peers[i]``, for every ``i``."""
        for p, obs, row in zip(peers, observations, u, strict=True):
            p.observation(obs, row)

    def action_rows(
        self,
        peers: Sequence[Disruptor],
        actions: Sequence[dict[str, Any]],
        u: Sequence[np.ndarray],
        rngs: Sequence[np.random.Generator],
    ) -> None:
        """`action` of ``actions[i]`` with ``u[i]`` by ``peers[i]`` (game ``i``'s generator)."""
        for p, acts, row, rng in zip(peers, actions, u, rngs, strict=True):
            p.action(acts, row, rng)


class AdditiveDisruptor(Disruptor):
    """A disruptor whose perturbation is ``unit * u``: `unit` maps normalized actions to raw units.

    `encode` inverts it (components with a zero budget encode to 0).
    """

    def __init__(
        self,
        spec: DisruptorSpec,
        unit: np.ndarray,
        bounded: bool = True,
        norm: str = "linf",
        blocks: Sequence[int] | None = None,
    ) -> None:
        super().__init__(spec, int(unit.shape[0]), bounded=bounded, norm=norm, blocks=blocks)
        self.unit = unit.astype(np.float64)
        self._peer_units: list[np.ndarray] = []  # the peers' units last found equal to ours

    def encode(self, value: Any) -> np.ndarray:
        """Perturbation in raw units -> normalized adversary action."""
        v = np.asarray(value, dtype=np.float64).reshape(self._batch_shape(value))
        if not self.bounded:
            return v.astype(np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(self.unit > 0, v / np.where(self.unit > 0, self.unit, 1.0), 0.0)
        return u.astype(np.float32)

    def perturbation(self, u: np.ndarray) -> np.ndarray:
        """The raw perturbation a (decoded) action, or a batch ``[N, size]`` of them, produces."""
        return u if not self.bounded else u * self.unit

    def _same_unit(self, peers: Sequence[Disruptor]) -> bool:
        """Whether every peer maps actions to perturbations as this one does (cached).

        `set_scale` (normalized-space budgets) gives a runtime a new `unit` array, so peers
        whose arrays are the ones found equal last time still are.
        """
        if not self.bounded:  # the action is the perturbation: no unit to agree on
            return True
        cached = self._peer_units
        if len(cached) == len(peers) and all(
            getattr(p, "unit", None) is c for p, c in zip(peers, cached, strict=True)
        ):
            return True
        units = [getattr(p, "unit", None) for p in peers]
        if all(isinstance(x, np.ndarray) and np.array_equal(x, self.unit) for x in units):
            self._peer_units = units  # type: ignore[assignment]
            return True
        return False


def split_blocks(vec: np.ndarray, targets: Sequence[str], sizes: Mapping[str, int]) -> dict:
    """Split a concatenated per-target vector into a dict of blocks."""
    out, i = {}, 0
    for t in targets:
        out[t] = vec[i : i + sizes[t]]
        i += sizes[t]
    return out
