"""Figures of a robust evaluation (a `PayoffTable`) and of training runs, as PNG files.

Plots use matplotlib's non-interactive Agg backend, imported only when a figure is drawn::

    plot_heatmap(table, "out/heatmap.png")
    plot_training_curves({"atla": "runs/atla/progress.csv"}, "out/training.png")
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from advgame.core.files import read_csv
from advgame.errors import ConfigError
from advgame.evaluation.table.payoff import PayoffTable, ci95

__all__ = [
    "X_COLUMNS",
    "method_series",
    "plot_budget_curve",
    "plot_heatmap",
    "plot_method_curves",
    "plot_safety",
    "plot_training_curves",
    "read_progress",
    "write_method_points",
]

log = logging.getLogger(__name__)

X_COLUMNS = ("iteration", "timesteps", "total_timesteps", "protagonist_steps", "step")
"""Progress-CSV columns tried, in order, for the x axis of training curves."""


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    _pyplot().close(fig)
    log.info("wrote %s", path)
    return path


def _panel_column(count: int, height: float) -> tuple[Any, list[Any]]:
    """A figure of `count` panels stacked in one column, `height` inches each."""
    fig, axes = _pyplot().subplots(
        count, 1, figsize=(6.5, height * count), squeeze=False, layout="constrained"
    )
    return fig, list(axes[:, 0])


def _finish_panel(ax: Any, ylabel: str) -> None:
    """Label a curves panel's y axis, add its grid and legend."""
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")


def plot_heatmap(table: PayoffTable, path: str | Path, stat: str = "mean", title: str = "") -> Path:
    """Draw protagonists × adversaries, the `stat` true return of each cell, annotated; save it.

    Cells not played are left blank, cells not applicable (`PayoffTable.not_applicable`) say
    "n/a". Returns the path of the PNG (or any matplotlib format).
    """
    plt = _pyplot()
    ps, adv, m = table.matrix(stat)
    if not ps:
        raise ConfigError("The payoff table is empty; evaluate some jobs before plotting it.")
    fig, ax = plt.subplots(figsize=(1.6 + 1.3 * len(adv), 1.2 + 0.6 * len(ps)))
    im = ax.imshow(np.ma.masked_invalid(m), cmap="viridis", aspect="auto")
    ax.set_xticks(range(len(adv)), adv, rotation=30, ha="right")
    ax.set_yticks(range(len(ps)), ps)
    lo, hi = (np.nanmin(m), np.nanmax(m)) if np.isfinite(m).any() else (0.0, 0.0)
    for (i, j), v in np.ndenumerate(m):
        if math.isfinite(v):
            dark = hi > lo and (v - lo) / (hi - lo) < 0.5
            ax.text(j, i, f"{v:.4g}", ha="center", va="center", color="w" if dark else "k")
        elif (ps[i], adv[j]) in table.not_applicable:
            ax.text(j, i, "n/a", ha="center", va="center", color="0.4")
    fig.colorbar(im, ax=ax, label=f"{stat} true return")
    ax.set_title(title or f"{stat} true return: protagonists × adversaries")
    return _save(fig, path)


def _budget_stats(rows: list[Mapping[str, Any]], budget: str) -> dict[str, dict[float, tuple]]:
    """Per protagonist, per budget: (mean true return, 95 % half-width over seed means)."""
    groups: dict[str, dict[float, dict[Any, list[float]]]] = {}
    for r in rows:
        seeds = groups.setdefault(r["protagonist"], {}).setdefault(float(r[budget]), {})
        seeds.setdefault(r["seed"], []).append(float(r["true_return"]))
    out: dict[str, dict[float, tuple]] = {}
    for p, by_budget in groups.items():
        for b, by_seed in sorted(by_budget.items()):
            episodes = [v for vs in by_seed.values() for v in vs]
            means = [float(np.mean(vs)) for vs in by_seed.values()]
            out.setdefault(p, {})[b] = (float(np.mean(episodes)), ci95(means))
    return out


def plot_budget_curve(
    data: PayoffTable | Iterable[Mapping[str, Any]],
    path: str | Path,
    budget: str = "budget",
    title: str = "",
) -> Path:
    """Draw mean true return against the `budget` column, one line per protagonist; save it.

    Bands are 95 % Student-t intervals over the seed means (drawn where there are >= 2 seeds).
    Rows without a `budget` value are ignored; `advgame.evaluation.budget_sweep` makes rows
    that have one.
    """
    rows = data.rows if isinstance(data, PayoffTable) else list(data)
    rows = [r for r in rows if r.get(budget) not in (None, "")]
    if not rows:
        raise ConfigError(f"No row has a {budget!r} column; build the jobs with budget_sweep().")
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    for p, curve in _budget_stats(rows, budget).items():
        x = np.array(list(curve))
        mean, half = (np.array(v) for v in zip(*curve.values(), strict=True))
        (line,) = ax.plot(x, mean, marker="o", label=p)
        ok = np.isfinite(half)
        if ok.any():
            ax.fill_between(
                x[ok], (mean - half)[ok], (mean + half)[ok], alpha=0.2, color=line.get_color()
            )
    ax.set_xlabel(budget)
    ax.set_ylabel("true return (mean, 95 % CI over seeds)")
    ax.set_title(title or "return vs budget")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, path)


def read_progress(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a run's ``progress.csv`` as float arrays (empty or non-numeric cells: nan)."""

    def num(text: str | None) -> float:
        try:
            return float(text) if text not in (None, "") else math.nan
        except ValueError:
            return math.nan

    fix = "It is rewritten by the run's next iteration (`advgame resume`), or delete the run."
    rows = read_csv(path, "progress file", fix, columns=())
    keys = list(dict.fromkeys(k for r in rows for k in r))
    return {k: np.array([num(r.get(k)) for r in rows]) for k in keys}


def plot_training_curves(
    progress_csv_paths: Mapping[str, str | Path],
    path: str | Path,
    x: str | None = None,
    columns: Sequence[str] | None = None,
) -> Path | None:
    """Draw training curves of runs' progress CSVs, one panel per column, one line per run.

    `x` defaults to the first of `X_COLUMNS` a run has; `columns` to every column whose name
    ends in ``return`` (``protagonist_return``, ``adversary_return``, ...). Missing files and
    columns are skipped with a warning; returns None (and writes nothing) if nothing is left.
    """
    runs = {}
    for name, csv_path in progress_csv_paths.items():
        if not Path(csv_path).is_file():
            log.warning("no progress CSV for run %r at %s; skipped", name, csv_path)
            continue
        runs[name] = read_progress(csv_path)
    wanted = (
        list(columns)
        if columns
        else [k for cols in runs.values() for k in cols if k.endswith("return")]
    )
    panels = [c for c in dict.fromkeys(wanted) if any(c in cols for cols in runs.values())]
    for c in set(wanted) - set(panels):
        log.warning("no run has the column %r; skipped", c)
    if not panels:
        log.warning("nothing to plot from %s", dict(progress_csv_paths))
        return None
    fig, axes = _panel_column(len(panels), 2.6)
    for ax, col in zip(axes, panels, strict=True):
        for name, cols in runs.items():
            xcol = x or next((k for k in X_COLUMNS if k in cols), None)
            if col in cols and (xcol in cols or xcol is None):
                xs = cols[xcol] if xcol else np.arange(len(cols[col]))
                ax.plot(xs, cols[col], marker=".", label=name)
                ax.set_xlabel(xcol or "row")
        _finish_panel(ax, col)
    return _save(fig, path)


def _padded(values: np.ndarray, n: int) -> np.ndarray:
    """`values` cut or nan-padded to length `n`."""
    return np.pad(values[:n], (0, n - len(values[:n])), constant_values=np.nan)


def method_series(
    groups: Mapping[str, Sequence[str | Path]],
    columns: Sequence[str],
    x: str = "protagonist_steps",
    ragged: bool = False,
) -> dict[str, dict[str, np.ndarray]]:
    """Each group's runs stacked per column: ``{label: {column: array [runs, points]}}``.

    `groups` maps a label to progress CSVs (missing files, and runs without `x` or one of
    `columns`, are skipped; so is a group left empty). Runs are cut to the shortest one's
    rows, or with `ragged` padded with nan to the longest one's: the curves of runs still in
    training, each point over the runs that have reached it.
    """
    data: dict[str, dict[str, np.ndarray]] = {}
    for label, paths in groups.items():
        found = [read_progress(p) for p in paths if Path(p).is_file()]
        runs = [r for r in found if x in r and all(c in r for c in columns)]
        if not runs:
            if found:  # a group with no runs yet (a campaign's pending method) is no surprise
                log.warning("no progress CSV of %r has %s; skipped", label, [x, *columns])
            continue
        lengths = [len(r[x]) for r in runs]
        n = max(lengths) if ragged else min(lengths)
        data[label] = {c: np.stack([_padded(r[c], n) for r in runs]) for c in (x, *columns)}
    return data


def _band(ys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean, minimum and maximum over runs (axis 0) of `ys`, ignoring nan.

    A nan is a run that has not reached the point; a point no run has reached is nan in all
    three.
    """
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(ys, axis=0), np.nanmin(ys, axis=0), np.nanmax(ys, axis=0)


def write_method_points(
    data: Mapping[str, Mapping[str, np.ndarray]],
    columns: Sequence[str],
    path: str | Path,
    x: str = "protagonist_steps",
) -> Path:
    """Write `method_series`' data as a CSV: per method and point, each column's mean, min, max.

    One row per method and point: ``method``, `x`, ``runs`` (how many have reached the point)
    and ``COLUMN_mean`` / ``_min`` / ``_max`` for each of `columns` (what `plot_method_curves`
    draws as the line and its band).
    """
    import csv

    path = Path(path)
    names = [f"{c}_{s}" for c in columns for s in ("mean", "min", "max")]
    with path.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["method", x, "runs", *names])
        for label, d in data.items():
            runs = np.sum(~np.isnan(d[columns[0]]), axis=0)
            bands = [np.stack(_band(d[c]), axis=1) for c in columns]  # [points, 3] per column
            for k, step in enumerate(np.nanmax(d[x], axis=0)):
                cells = [f"{v:.6g}" for band in bands for v in band[k]]
                out.writerow([label, f"{step:.0f}", int(runs[k]), *cells])
    return path


def plot_method_curves(
    groups: Mapping[str, Sequence[str | Path]],
    path: str | Path,
    columns: Sequence[str],
    x: str = "protagonist_steps",
    lines: Mapping[str, float] | None = None,
    ragged: bool = False,
    title: str = "",
) -> Path | None:
    """Draw each group's (method's) mean training curve over its runs, with their min-max band.

    `groups` maps a label to the progress CSVs of its runs (seeds); one panel per column of
    `columns`; runs are cut to the shortest one's rows, or with `ragged` each point is over the
    runs that have reached it (`method_series`). `lines` draws a dashed horizontal line on a
    column's panel (a cost limit); `title` heads the figure. Runs without the columns are
    skipped; returns None (and writes nothing) if nothing is left. The numbers drawn go beside
    the figure, in a CSV of the same name (`write_method_points`).
    """
    data = method_series(groups, columns, x, ragged)
    if not data:
        return None
    write_method_points(data, columns, Path(path).with_suffix(".csv"), x)
    fig, axes = _panel_column(len(columns), 2.8)
    if title:
        fig.suptitle(title)
    for ax, col in zip(axes, columns, strict=True):
        for label, d in data.items():
            xs, ys = np.nanmax(d[x], axis=0), d[col]
            mean, low, high = _band(ys)
            (line,) = ax.plot(xs, mean, label=f"{label} ({len(ys)})")
            ax.fill_between(xs, low, high, color=line.get_color(), alpha=0.2)
        if lines and col in lines:
            ax.axhline(lines[col], color="k", linestyle="--", linewidth=1, label="limit")
        ax.set_xlabel(x)
        _finish_panel(ax, col)
    return _save(fig, path)


def plot_safety(table: PayoffTable, path: str | Path, limit: float) -> Path:
    """Draw each cell's mean episode cost (x, 95 % CI) against its mean true return; save it.

    One marker per protagonist, one point per adversary; the dashed line is the cost `limit`.
    """
    plt = _pyplot()
    rows = table.safety(limit)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for k, p in enumerate(table.protagonists):
        mine = [r for r in rows if r["protagonist"] == p]
        err = [0.0 if math.isnan(r["cost_ci95"]) else r["cost_ci95"] for r in mine]
        ax.errorbar(
            [r["cost"] for r in mine],
            [r["return"] for r in mine],
            xerr=err,
            fmt="osD^v"[k % 5],
            label=p,
            capsize=3,
        )
        for r in mine:
            ax.annotate(r["adversary"], (r["cost"], r["return"]), fontsize=7)
    ax.axvline(limit, color="k", linestyle="--", linewidth=1, label=f"limit {limit:g}")
    ax.set(xlabel="mean true episode cost", ylabel="mean true return")
    ax.legend(fontsize=8)
    return _save(fig, path)
