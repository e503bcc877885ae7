"""Formatting shared by the reproduction scripts: means with 95 % intervals over seeds."""

from __future__ import annotations

import numpy as np

from advgame.payoff import ci95


def fmt(values: list[float]) -> str:
    """``"mean ± half-width"`` of `values` (95 % Student-t interval), rounded to integers."""
    return f"{float(np.mean(values)):.0f} ± {ci95(values):.0f}"
