"""Helpers shared by the benchmark and reproduction scripts."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from advgame.evaluation.payoff import ci95


def fmt(values: list[float]) -> str:
    """``"mean ± half-width"`` of `values` (95 % Student-t interval), rounded to integers."""
    return f"{float(np.mean(values)):.0f} ± {ci95(values):.0f}"


def step_through(env: Any, actions: np.ndarray) -> float:
    """Step a Gymnasium env with each of `actions` (resetting at episode ends); wall seconds."""
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return time.perf_counter() - start


def quartiles(values: list[float]) -> str:
    """``"median (q1-q3)"`` of `values`, two decimals: how the per-round ratios are reported."""
    q1, q2, q3 = np.percentile(values, [25, 50, 75])
    return f"{q2:.2f} ({q1:.2f}-{q3:.2f})"


def ratio_row(name: str, rates: dict[str, list[float]]) -> str:
    """A Markdown row: median raw steps/s, then every other variant's per-round ratio to raw.

    `rates` maps ``"raw"`` and each variant to its steps/s in the same interleaved rounds.
    """
    import statistics

    cells = [
        quartiles([v / w for v, w in zip(values, rates["raw"], strict=True)])
        for key, values in rates.items()
        if key != "raw"
    ]
    return f"| {name} | {statistics.median(rates['raw']):.0f} | " + " | ".join(cells) + " |"
