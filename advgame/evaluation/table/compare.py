"""What a table can conclude about two methods: each finding with its interval over agents and a test.

A campaign's table holds, for each agent (one trained run), its mean true return in each column
(a test condition: a preset, an attack). Two kinds of question, each answered over *agents*,
not over the evaluation seeds of one agent (seeds measure one policy; agents measure a method):

* `compare_methods`: do two methods differ in one column? The difference of their means over
  agents, Welch's 95 % interval (the t quantile at the Welch-Satterthwaite degrees of freedom,
  rounded down), and the exact two-sided permutation test over the agents' labels.
* `compare_columns`: does one method's return change from one column to another (the same
  agents on both)? The mean paired change, its Student-t 95 % interval, and the exact
  two-sided sign-flip test over the agents' changes.

Both tests are exact and need no distributional assumption; with three agents a side they
cannot go below p = 0.1 (two-sided: 2 of the 20 splits, 2 of the 8 sign patterns), so three
seeds never *establish* a difference at the 5 % level, whatever the interval says. A
`Comparison` says so in its `sentence`.

Example:
    >>> rows = [{"protagonist": f"{m}-s{s}", "adversary": "nominal", "seed": 0,
    ...          "true_return": r} for m, s, r in
    ...         [("a", 0, 10.0), ("a", 1, 12.0), ("a", 2, 11.0),
    ...          ("b", 0, 20.0), ("b", 1, 25.0), ("b", 2, 22.0)]]
    >>> c = compare_methods(agent_means(rows), "a", "b", "nominal")
    >>> round(c.difference, 2), c.p_value
    (11.33, 0.1)

"""

from __future__ import annotations

import itertools
import math
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from advgame.errors import ConfigError
from advgame.evaluation.table.payoff import _T975, ci95

__all__ = [
    "Comparison",
    "agent_means",
    "compare_columns",
    "compare_methods",
    "method_of",
]


def method_of(agent: str) -> str:
    """A campaign run's method: its name less the ``-s<seed>`` suffix (``sac-rsc-matched-s2``)."""
    head, sep, tail = agent.rpartition("-s")
    return head if sep and tail.isdigit() else agent


def agent_means(rows: Iterable[Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    """``{agent: {column: mean true return}}`` from payoff rows (`PayoffTable` or its CSV)."""
    sums: dict[tuple[str, str], list[float]] = defaultdict(list)
    for row in rows:
        value = row.get("true_return")
        if value in (None, ""):
            continue  # a cell not applicable
        sums[(str(row["protagonist"]), str(row["adversary"]))].append(float(value))
    out: dict[str, dict[str, float]] = defaultdict(dict)
    for (agent, column), values in sums.items():
        out[agent][column] = float(np.mean(values))
    return dict(out)


@dataclass(frozen=True)
class Comparison:
    """One finding: ``difference = mean(b) − mean(a)`` with its interval and exact test."""

    a: str
    """The first side: a method (`compare_methods`) or a column (`compare_columns`)."""
    b: str
    """The second side."""
    where: str
    """The column compared (`compare_methods`) or the method (`compare_columns`)."""
    values_a: tuple[float, ...]
    """Side a's values, one per agent."""
    values_b: tuple[float, ...]
    """Side b's values, one per agent (the same agents, in order, for `compare_columns`)."""
    difference: float
    """``mean(b) − mean(a)``."""
    half_width: float
    """Half-width of its 95 % interval (nan when a side has one agent)."""
    p_value: float
    """The exact two-sided test's p: permutation (methods) or sign-flip (columns)."""
    test: str
    """The test's name."""

    @property
    def low(self) -> float:
        """The interval's lower end."""
        return self.difference - self.half_width

    @property
    def high(self) -> float:
        """The interval's upper end."""
        return self.difference + self.half_width

    @property
    def resolved(self) -> bool:
        """Whether the test rejects "no difference" at 5 %: never with 3 agents a side."""
        return self.p_value < 0.05

    def sentence(self) -> str:
        """The finding in words: means, difference, interval, test, and what it cannot tell."""
        mean_a, mean_b = float(np.mean(self.values_a)), float(np.mean(self.values_b))
        text = (
            f"{self.where}: {self.b} {mean_b:,.0f} vs {self.a} {mean_a:,.0f} "
            f"(n = {len(self.values_b)} and {len(self.values_a)}), difference "
            f"{self.difference:+,.0f}, 95 % interval [{self.low:+,.0f}, {self.high:+,.0f}], "
            f"{self.test} p = {self.p_value:.2f}"
        )
        if self.resolved:
            return text + "."
        floor = _smallest_p(self)
        if floor < 0.05:
            return text + ": the data cannot tell them apart."
        n = f"{len(self.values_a)} and {len(self.values_b)} agents"
        if self.low > 0 or self.high < 0:
            return (
                text
                + f": the interval excludes 0, but with {n} the test cannot go below p = {floor:.2f}."
            )
        return (
            text
            + f": the data cannot tell them apart (with {n} the test cannot go below p = {floor:.2f})."
        )


def compare_methods(
    means: Mapping[str, Mapping[str, float]], a: str, b: str, column: str
) -> Comparison:
    """Methods `a` and `b` in `column`: Welch's interval and the exact permutation test."""
    va, vb = _values(means, a, column), _values(means, b, column)
    difference = float(np.mean(vb) - np.mean(va))
    half = math.nan
    if len(va) > 1 and len(vb) > 1:
        sa, sb = np.var(va, ddof=1) / len(va), np.var(vb, ddof=1) / len(vb)
        se = math.sqrt(sa + sb)
        if se > 0:
            df = (sa + sb) ** 2 / (sa**2 / (len(va) - 1) + sb**2 / (len(vb) - 1))
            half = _t975(int(df)) * se
        else:
            half = 0.0
    pooled = np.array(va + vb)
    observed = abs(difference)
    splits = list(itertools.combinations(range(len(pooled)), len(va)))
    extreme = 0
    for chosen in splits:
        mask = np.zeros(len(pooled), dtype=bool)
        mask[list(chosen)] = True
        if abs(pooled[~mask].mean() - pooled[mask].mean()) >= observed - 1e-9:
            extreme += 1
    return Comparison(a, b, column, tuple(va), tuple(vb), difference, half,
                      extreme / len(splits), "exact permutation test")  # fmt: skip


def compare_columns(
    means: Mapping[str, Mapping[str, float]], method: str, a: str, b: str
) -> Comparison:
    """Method `method`'s agents from column `a` to `b`: paired change, sign-flip test."""
    agents = _agents(means, method)
    missing = [g for g in agents if a not in means[g] or b not in means[g]]
    if missing:
        raise ConfigError(f"Agents {missing} of {method!r} lack column {a!r} or {b!r}.")
    va = [means[g][a] for g in agents]
    vb = [means[g][b] for g in agents]
    change = np.array(vb) - np.array(va)
    observed = abs(change.mean())
    signs = list(itertools.product((1.0, -1.0), repeat=len(change)))
    extreme = sum(abs((change * s).mean()) >= observed - 1e-9 for s in map(np.array, signs))
    return Comparison(a, b, method, tuple(va), tuple(vb), float(change.mean()), ci95(change),
                      extreme / len(signs), "exact sign-flip test")  # fmt: skip


def _agents(means: Mapping[str, Mapping[str, float]], method: str) -> list[str]:
    agents = sorted(g for g in means if method_of(g) == method)
    if not agents:
        known = sorted({method_of(g) for g in means})
        raise ConfigError(f"No agent of method {method!r} in the table; it has {known}.")
    return agents


def _values(means: Mapping[str, Mapping[str, float]], method: str, column: str) -> list[float]:
    agents = _agents(means, method)
    missing = [g for g in agents if column not in means[g]]
    if missing:
        columns = sorted({c for g in agents for c in means[g]})
        raise ConfigError(f"Agents {missing} have no column {column!r}; the table has {columns}.")
    return [means[g][column] for g in agents]


def _t975(df: int) -> float:
    return _T975[max(df, 1) - 1] if df <= len(_T975) else 1.96


def _smallest_p(c: Comparison) -> float:
    """The smallest p the comparison's test can give with these numbers of agents."""
    if c.test == "exact sign-flip test":
        return 2 / 2 ** len(c.values_a)
    splits = math.comb(len(c.values_a) + len(c.values_b), len(c.values_a))
    return (2 if len(c.values_a) == len(c.values_b) else 1) / splits
