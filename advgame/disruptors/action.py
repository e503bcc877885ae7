"""The action disruptor: additive, probabilistic and noisy action-robust forms, and discrete.

* ``"additive"``: ``a~ = clip(a + ε·u)`` into the protagonist's action space.
* ``"probabilistic"`` (Tessler et al. 2019, PR-MDP): with probability α the adversary's action
  ``ā`` replaces the protagonist's. For a `Discrete` action space ``ā = argmax(u)``.
* ``"noisy"`` (Tessler et al. 2019, NR-MDP): ``a~ = (1 - α)·a + α·ā``.

For the probabilistic and noisy forms, ``u ∈ [-1, 1]^n`` maps linearly onto the action bounds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, cast

import numpy as np
from gymnasium import spaces

from advgame.core.checks import clip_ufunc
from advgame.core.disruptor import (
    AdditiveDisruptor,
    Disruptor,
    DisruptorSpec,
    as_budget,
    budget_array,
    resolve_targets,
)
from advgame.errors import BudgetError, ConfigError

if TYPE_CHECKING:
    from advgame.core.task import TaskBase

__all__ = ["ActionDisruptor", "ActionRuntime"]

MODES = ("additive", "probabilistic", "noisy")


@dataclass(frozen=True, kw_only=True)
class ActionDisruptor(DisruptorSpec):
    """Perturb the action protagonists send to the simulator.

    Example:
        >>> import advgame
        >>> game = advgame.make("Hopper-v5", disruptors=[ActionDisruptor(eps=0.1)])
        >>> game.action_space("action_adversary").shape
        (3,)

    """

    kind = "action"
    budget_fields = ("eps",)
    mode: Literal["additive", "probabilistic", "noisy"] = "additive"
    """Which action-robust form (see the module docstring)."""
    eps: float | Sequence[float] = 0.1
    """Additive budget per action dimension (``mode="additive"``)."""
    alpha: float = 0.1
    """Probability of replacement, or mixing weight (``"probabilistic"``, ``"noisy"``)."""
    targets: Sequence[str] | None = None
    """Protagonists whose actions are perturbed (``None``: all)."""
    bounded: bool = True
    """``False``: additive, unbounded (the paper's random mode); the action is the raw offset."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.mode not in MODES:
            raise ConfigError(f"mode must be one of {MODES}, got {self.mode!r}.")
        if not (0.0 <= float(self.alpha) <= 1.0):
            raise BudgetError(f"ActionDisruptor.alpha must be in [0, 1], got {self.alpha!r}.")
        if self.mode == "additive" and self.bounded:
            eps = budget_array(self.eps, "ActionDisruptor.eps")
            as_budget(self.eps, eps.size if eps.ndim else 1, "ActionDisruptor.eps")
        if self.mode != "additive" and not self.bounded:
            raise ConfigError("bounded=False applies only to mode='additive'.")

    def build(self, task: TaskBase) -> ActionRuntime:
        """Bind to `task`, checking that each target's action space fits the mode."""
        targets = resolve_targets(task, self.targets)
        for t in targets:
            space = task.action_spaces[t]
            if isinstance(space, spaces.Discrete) and self.mode != "probabilistic":
                raise ConfigError(
                    f"{t!r} has a Discrete action space; use ActionDisruptor(mode='probabilistic') "
                    f"(the adversary's choice replaces the action with probability alpha), not {self.mode!r}."
                )
            if not isinstance(space, (spaces.Box, spaces.Discrete)):
                raise ConfigError(
                    f"{t!r} has action space {space}; only Box and Discrete are supported."
                )
        return ActionRuntime(self, task, targets)


class ActionRuntime(AdditiveDisruptor):
    """`ActionDisruptor` bound to a task."""

    hook = "action"

    def __init__(self, spec: ActionDisruptor, task: TaskBase, targets: tuple[str, ...]) -> None:
        self.targets = targets
        self.mode = spec.mode
        self.alpha = float(spec.alpha)
        # build() checked that every target acts in a Box or a Discrete space
        self.spaces: dict[str, spaces.Box | spaces.Discrete] = {
            t: cast(spaces.Box | spaces.Discrete, task.action_spaces[t]) for t in targets
        }
        self.sizes = {t: _size(s) for t, s in self.spaces.items()}
        units = []
        for t in targets:
            s = self.spaces[t]
            if spec.mode == "additive":
                eps = (
                    as_budget(spec.eps, self.sizes[t], "ActionDisruptor.eps")
                    if spec.bounded
                    else np.ones(self.sizes[t])
                )
                units.append(eps)
            elif isinstance(s, spaces.Box):
                units.append((s.high - s.low).reshape(-1) / 2.0)
            else:
                units.append(np.ones(self.sizes[t]))
        super().__init__(
            spec,
            np.concatenate(units),
            bounded=spec.bounded,
            blocks=[self.sizes[t] for t in targets],
        )
        self._plan = self._blocks()
        self._flat = spec.mode in ("additive", "noisy") and all(
            isinstance(space, spaces.Box) and len(space.shape) == 1 for _, _, space, _ in self._plan
        )  # deterministic and whole 1-D Boxes: `action_rows` stacks them
        t0, block0, space0, bounds0 = self._plan[0]
        self._lone = (
            (t0, space0, bounds0)
            if spec.mode == "additive" and len(self._plan) == 1 and block0 is None
            and isinstance(space0, spaces.Box)
            else None
        )  # fmt: skip
        """(target, space, bounds) when `action` has one additive whole-Box target, else None."""

    def encode(self, value: Any) -> np.ndarray:
        """Raw units -> adversary action: an offset (additive) or the adversary's own action."""
        if self.mode == "additive":
            return super().encode(value)
        if np.ndim(value) == 2:
            return np.stack([self.encode(row) for row in value])
        out, i = [], 0
        flat = np.asarray(value, dtype=np.float64).reshape(-1)
        for t in self.targets:
            space, n = self.spaces[t], self.sizes[t]
            if isinstance(space, spaces.Discrete):
                onehot = -np.ones(n)
                onehot[int(flat[i]) - int(space.start)] = 1.0
                out.append(onehot)
                i += 1
            else:
                v = flat[i : i + n]
                out.append(2.0 * (v - space.low) / (space.high - space.low) - 1.0)
                i += n
        return np.concatenate(out).astype(np.float32)

    def _blocks(self) -> list[tuple[str, slice | None, Any, tuple[np.ndarray, np.ndarray]]]:
        """Per target: its block of ``u`` and `unit` (``None``: all), its space, its bounds.

        Box bounds are kept in float64, the dtype of the disrupted action before its final
        cast: clipping against float32 bounds would convert them (exactly) every call.
        """
        out, i = [], 0
        for t in self.targets:
            n, space = self.sizes[t], self.spaces[t]
            block = None if n == self.shape[0] else slice(i, i + n)
            if isinstance(space, spaces.Box):
                bounds = (space.low.astype(np.float64), space.high.astype(np.float64))
            else:
                bounds = (np.zeros(0), np.zeros(0))  # unused: Discrete actions are replaced
            out.append((t, block, space, bounds))
            i += n
        return out

    def action(self, actions: dict[str, Any], u: np.ndarray, rng: np.random.Generator) -> None:
        """Replace each target's action by its disrupted version (`moved`, or a draw)."""
        if self._lone is not None:  # additive on one whole Box: the loop below, its one case
            t, space, bounds = self._lone
            a = actions[t]
            if type(a) is np.ndarray and a.dtype.kind == "f" and a.dtype.itemsize <= 8:
                actions[t] = self.moved(a, u, None, space, bounds)
                return
        for t, block, space, bounds in self._plan:
            b = u if block is None else u[block]
            if isinstance(space, spaces.Discrete):
                if rng.random() < self.alpha:
                    actions[t] = np.int64(space.start + int(np.argmax(b)))
                continue
            a = _as_float(np.asarray(actions[t]))
            if self.mode == "probabilistic":
                new = _adversary_action(b, space) if rng.random() < self.alpha else a
                actions[t] = clip_ufunc(new, *bounds).astype(space.dtype)
            else:
                actions[t] = self.moved(a, b, block, space, bounds)

    def action_rows(
        self,
        peers: Sequence[Disruptor],
        actions: Sequence[dict[str, Any]],
        u: Any,
        rngs: Sequence[np.random.Generator],
    ) -> None:
        """`action` over N alike games at once: their rows stacked, then `action_array`.

        The probabilistic mode and Discrete actions draw from each game's own generator, and
        peers with another budget disrupt their own rows, so each peer then acts on its own.
        """
        if not (self._flat and isinstance(u, np.ndarray) and self._same_unit(peers)):
            super().action_rows(peers, actions, u, rngs)
            return
        stacked = {t: np.array([acts[t] for acts in actions]) for t in self.targets}
        self.action_array(stacked, u, rngs)  # np.array of the rows: np.stack's value, faster
        for t, rows in stacked.items():
            for acts, row in zip(actions, rows, strict=True):
                acts[t] = row

    def action_array(
        self, actions: dict[str, np.ndarray], u: np.ndarray, rngs: Sequence[np.random.Generator]
    ) -> None:
        """`action` of every row at once (additive and noisy modes on 1-D Boxes: no draws).

        Each row gets exactly the single copy's value (the same `moved`); the probabilistic
        mode and Discrete actions draw from each copy's own generator, row by row.
        """
        if not self._flat:
            super().action_array(actions, u, rngs)
            return
        for t, block, space, bounds in self._plan:
            b = u if block is None else u[:, block]
            actions[t] = self.moved(_as_float(actions[t]), b, block, space, bounds)

    def moved(
        self, a: np.ndarray, b: np.ndarray, block: Any, space: spaces.Box, bounds: Any
    ) -> np.ndarray:
        """Action `a` of one Box target moved by the adversary's `b`, clipped, cast to the space.

        The additive or noisy mode's arithmetic, the one implementation that the single game,
        the lockstep rows and the array game all apply: `a` and `b` are one action ``[n]`` or
        rows ``[M, n]`` alike (`block`: the target's part of `unit`; `a` a float array).
        """
        if self.mode == "additive":
            new = a + b * (self.unit if block is None else self.unit[block])
        else:
            # float64 first: a float32 `a` times a Python float would stay float32
            new = (1.0 - self.alpha) * a.astype(np.float64) + self.alpha * _adversary_action(
                b, space
            )
        return clip_ufunc(new, *bounds).astype(space.dtype)  # `ndarray.clip`'s own ufunc


def _as_float(a: np.ndarray) -> np.ndarray:
    """`a` as it enters the float64 sums: a float array as it is (exactly its float64 copy)."""
    return a if a.dtype.kind == "f" and a.dtype.itemsize <= 8 else a.astype(np.float64)


def _adversary_action(b: np.ndarray, space: spaces.Box) -> np.ndarray:
    """The adversary's own action ``ā``: ``u ∈ [-1, 1]`` mapped linearly onto the space's bounds."""
    return space.low + (b + 1.0) * 0.5 * (space.high - space.low)


def _size(space: spaces.Box | spaces.Discrete) -> int:
    return int(space.n) if isinstance(space, spaces.Discrete) else int(np.prod(space.shape))
