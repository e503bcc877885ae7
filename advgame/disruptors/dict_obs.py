"""Dictionary observations: the leaves an observation disruptor may perturb, and how.

Goal-conditioned tasks (gymnasium-robotics) observe a `gymnasium.spaces.Dict`: ``observation``,
``achieved_goal`` and ``desired_goal``, and Franka Kitchen nests a dict of per-task goals under
each goal key. A *leaf* is a `Box` inside the Dict, named by its path joined with ``/``
(``"achieved_goal/kettle"``); a *key* given by the user names a leaf or a whole sub-dict
(``"achieved_goal"`` covers every task's goal in Kitchen).

Order (documented, and what the adversary's flat action is): the keys in the order the user
gives them, and within a key its leaves in the Dict space's own order, depth first. Gymnasium
sorts the keys of a Dict built from a plain dict, so the default (every leaf) is alphabetical:
``achieved_goal``, ``desired_goal``, ``observation``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from advgame.core.disruptor import as_budget
from advgame.errors import BudgetError, ConfigError, UnknownNameError, did_you_mean

__all__ = ["SEP", "Leaf", "flat_space", "flatten", "layout", "leaves", "perturb"]

SEP = "/"
"""Joins the keys of a nested path into a leaf name."""


@dataclass(frozen=True)
class Leaf:
    """One perturbed `Box` of a Dict observation and its block of the adversary's action."""

    name: str
    """The leaf's path joined with ``/``."""
    key: str
    """The user's key that selected it (its budget's name)."""
    path: tuple[str, ...]
    """Keys from the root of the observation to the leaf."""
    block: slice
    """Its components in the flat perturbation vector."""
    space: spaces.Box
    """The leaf's space."""
    bounds: tuple[np.ndarray, np.ndarray] | None
    """Float64 clip bounds when the space is bounded, else None."""


def leaves(space: spaces.Dict, prefix: str = "") -> list[tuple[str, spaces.Box]]:
    """Every `Box` leaf of `space` with its name, in the space's order, depth first."""
    out: list[tuple[str, spaces.Box]] = []
    for key, sub in space.spaces.items():
        name = f"{prefix}{key}"
        if isinstance(sub, spaces.Dict):
            out.extend(leaves(sub, name + SEP))
        elif isinstance(sub, spaces.Box):
            out.append((name, sub))
        else:
            raise ConfigError(
                f"Observation part {name!r} is {sub}; only Box leaves of a Dict observation "
                "can be perturbed or flattened."
            )
    return out


def flat_space(space: spaces.Dict) -> spaces.Box:
    """A float64 `Box` holding every leaf of `space`, concatenated in leaf order."""
    parts = leaves(space)
    low = np.concatenate([s.low.astype(np.float64).reshape(-1) for _, s in parts])
    high = np.concatenate([s.high.astype(np.float64).reshape(-1) for _, s in parts])
    return spaces.Box(low, high, dtype=np.float64)


def _get(obs: Mapping[str, Any], path: Sequence[str]) -> Any:
    for key in path:
        obs = obs[key]
    return obs


def flatten(obs: Mapping[str, Any], names: Sequence[str]) -> np.ndarray:
    """The leaves `names` of a Dict observation, raveled and concatenated (float64)."""
    return np.concatenate(
        [np.asarray(_get(obs, n.split(SEP)), dtype=np.float64).reshape(-1) for n in names]
    )


def layout(space: spaces.Dict, keys: Sequence[str] | None) -> list[Leaf]:
    """The leaves `keys` select (every leaf if None), each with its block of the perturbation.

    Example:
        >>> box = spaces.Box(-1.0, 1.0, (2,))
        >>> space = spaces.Dict({"observation": spaces.Box(-1.0, 1.0, (4,)), "desired_goal": box})
        >>> [(leaf.name, leaf.block) for leaf in layout(space, ["observation", "desired_goal"])]
        [('observation', slice(0, 4, None)), ('desired_goal', slice(4, 6, None))]
        >>> [leaf.name for leaf in layout(space, None)]  # default: the space's (sorted) order
        ['desired_goal', 'observation']

    """
    table = leaves(space)
    names = [n for n, _ in table]
    out: list[Leaf] = []
    seen: set[str] = set()
    i = 0
    for key in keys if keys is not None else names:
        matched = [(n, s) for n, s in table if n == key or n.startswith(key + SEP)]
        if not matched:
            known = sorted({*names, *(n.split(SEP)[0] for n in names)})
            raise UnknownNameError(
                f"No observation key {key!r}.{did_you_mean(key, known)} Keys: {known} "
                f"(nested keys are joined with {SEP!r})."
            )
        for name, box in matched:
            if name in seen:
                raise ConfigError(f"Observation key {name!r} is selected twice in keys={keys!r}.")
            seen.add(name)
            n = int(np.prod(box.shape))
            bounded = bool(np.isfinite(box.low).any() or np.isfinite(box.high).any())
            bounds = (box.low.astype(np.float64), box.high.astype(np.float64))
            out.append(
                Leaf(
                    name,
                    key,
                    tuple(name.split(SEP)),
                    slice(i, i + n),
                    box,
                    bounds if bounded else None,
                )
            )
            i += n
    return out


def key_blocks(plan: Sequence[Leaf]) -> list[int]:
    """Sizes of each user key's block, in order (the L2 ball is per key)."""
    sizes: dict[str, int] = {}
    for leaf in plan:
        sizes[leaf.key] = sizes.get(leaf.key, 0) + leaf.block.stop - leaf.block.start
    return list(sizes.values())


def budget(plan: Sequence[Leaf], eps: Any) -> np.ndarray:
    """ε per perturbed component: a scalar, one value per component, or a mapping per key.

    With a mapping, a key's value is a scalar or one value per component of that key.
    """
    total = plan[-1].block.stop if plan else 0
    if not isinstance(eps, Mapping):
        return as_budget(eps, total, "ObservationDisruptor.eps")
    out = np.zeros(total)
    for key in dict.fromkeys(leaf.key for leaf in plan):
        if key not in eps:
            raise BudgetError(
                f"ObservationDisruptor.eps has no budget for key {key!r}; give one per attacked "
                f"key, e.g. eps={{{key!r}: 0.01, ...}}. Budgets given: {list(eps)}."
            )
        part = [leaf for leaf in plan if leaf.key == key]
        lo, hi = part[0].block.start, part[-1].block.stop
        out[lo:hi] = as_budget(eps[key], hi - lo, f"ObservationDisruptor.eps[{key!r}]")
    return out


def perturb(obs: Mapping[str, Any], plan: Sequence[Leaf], delta: np.ndarray) -> dict[str, Any]:
    """A copy of `obs` with ``δ`` added to the planned leaves (clipped into their spaces).

    Only the dicts along a perturbed path are copied; `obs` itself is never written, so the
    true observation the task keeps stays true.
    """
    out = dict(obs)
    for leaf in plan:
        node = out
        for key in leaf.path[:-1]:
            node[key] = dict(node[key])  # copy each level before writing into it
            node = node[key]
        last = leaf.path[-1]
        value = np.asarray(node[last], dtype=np.float64)
        new = value + delta[leaf.block].reshape(value.shape)
        if leaf.bounds is not None:
            new = new.clip(*leaf.bounds)
        node[last] = new.astype(leaf.space.dtype, copy=False)
    return out
