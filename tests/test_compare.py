"""Comparisons over agents: the interval and the exact tests, computed by hand on small tables."""

from __future__ import annotations

import math

import pytest

from advgame.errors import ConfigError
from advgame.evaluation.table.compare import (
    agent_means,
    compare_columns,
    compare_methods,
    method_of,
)


def _rows(values: dict[str, dict[str, list[float]]]) -> list[dict]:
    return [
        {"protagonist": agent, "adversary": column, "seed": seed, "true_return": r}
        for agent, columns in values.items()
        for column, returns in columns.items()
        for seed, r in enumerate(returns)
    ]


MEANS = agent_means(
    _rows(
        {
            "a-s0": {"x": [9.0, 11.0], "y": [4.0]},
            "a-s1": {"x": [12.0], "y": [8.0]},
            "a-s2": {"x": [11.0], "y": [5.0]},
            "b-s0": {"x": [20.0], "y": [21.0]},
            "b-s1": {"x": [25.0], "y": [20.0]},
            "b-s2": {"x": [22.0], "y": [26.0]},
        }
    )
)


def test_agent_means_average_seeds_and_method_names_drop_the_seed() -> None:
    assert MEANS["a-s0"] == {"x": 10.0, "y": 4.0}
    assert method_of("sac-rsc-matched-s2") == "sac-rsc-matched" and method_of("sac") == "sac"
    assert method_of("ompo-s1x") == "ompo-s1x"


def test_methods_welch_interval_and_exact_permutation_p() -> None:
    c = compare_methods(MEANS, "a", "b", "x")
    a, b = [10.0, 12.0, 11.0], [20.0, 25.0, 22.0]
    assert c.difference == pytest.approx(sum(b) / 3 - sum(a) / 3)
    va, vb = 1.0 / 3, (19 / 3) / 3  # sample variances 1 and 19/3, over n = 3
    df = (va + vb) ** 2 / (va**2 / 2 + vb**2 / 2)
    assert int(df) == 2
    assert c.half_width == pytest.approx(4.303 * math.sqrt(va + vb))
    # every b above every a: only the observed split and its mirror are as extreme
    assert c.p_value == pytest.approx(2 / 20)
    assert not c.resolved and "cannot go below p = 0.10" in c.sentence()


def test_overlapping_methods_get_a_large_p() -> None:
    means = {"a-s0": {"x": 1.0}, "a-s1": {"x": 3.0}, "b-s0": {"x": 2.0}, "b-s1": {"x": 4.0}}
    c = compare_methods(means, "a", "b", "x")
    # splits of {1, 2, 3, 4} into two pairs: |diff| >= 1 for (1,3)|(2,4), (2,4)|(1,3),
    # (1,2)|(3,4), (3,4)|(1,2): 4 of 6
    assert c.p_value == pytest.approx(4 / 6)
    assert "cannot tell them apart" in c.sentence()


def test_columns_paired_change_and_sign_flip_p() -> None:
    c = compare_columns(MEANS, "a", "x", "y")
    changes = [-6.0, -4.0, -6.0]
    assert c.difference == pytest.approx(sum(changes) / 3)
    mean = sum(changes) / 3
    sd = math.sqrt(sum((v - mean) ** 2 for v in changes) / 2)
    assert c.half_width == pytest.approx(4.303 * sd / math.sqrt(3))
    assert c.p_value == pytest.approx(2 / 8)  # all negative: itself and all-positive
    mixed = compare_columns(MEANS, "b", "x", "y")  # +1, -5, +4: mean 0
    assert mixed.p_value == pytest.approx(1.0)


def test_many_agents_can_resolve_a_difference() -> None:
    means = {f"a-s{i}": {"x": float(i)} for i in range(5)}
    means |= {f"b-s{i}": {"x": 100.0 + i} for i in range(5)}
    c = compare_methods(means, "a", "b", "x")
    assert c.p_value == pytest.approx(2 / 252) and c.resolved
    assert c.sentence().endswith("p = 0.01.")


def test_unknown_method_or_column_is_a_clear_error() -> None:
    with pytest.raises(ConfigError, match=r"No agent of method 'c'.*'a', 'b'"):
        compare_methods(MEANS, "a", "c", "x")
    with pytest.raises(ConfigError, match="no column 'z'"):
        compare_methods(MEANS, "a", "b", "z")
