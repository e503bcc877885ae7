"""Statistics shared by the reproduction scripts: means with Student-t intervals over seeds."""

from __future__ import annotations

import math

import numpy as np


def interval(values: list[float]) -> tuple[float, float]:
    """Mean of `values` and the half-width of its 95 % Student-t interval (NaN for one value)."""
    from scipy import stats

    mean = float(np.mean(values))
    if len(values) < 2:
        return mean, math.nan
    half = float(
        stats.t.ppf(0.975, len(values) - 1) * np.std(values, ddof=1) / math.sqrt(len(values))
    )
    return mean, half


def fmt(values: list[float]) -> str:
    """``"mean ± half-width"`` of `values`, rounded to integers."""
    mean, half = interval(values)
    return f"{mean:.0f} ± {half:.0f}"
