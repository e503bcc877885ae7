"""Figures and a Markdown report of a robust evaluation (a `PayoffTable`) and of training runs.

Plots use matplotlib's non-interactive Agg backend, imported only when a figure is drawn::

    table = evaluate(jobs, workers=2)
    plot_heatmap(table, "out/heatmap.png")
    write_report("out", "Hopper robustness", table)  # -> out/report.md
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from advgame.core.files import read_csv, read_json
from advgame.errors import ConfigError
from advgame.evaluation import NOMINAL, PayoffTable, ci95

__all__ = [
    "DEFAULT_COST_LIMIT",
    "adversary_listing",
    "meta_game_section",
    "plot_budget_curve",
    "plot_heatmap",
    "plot_safety",
    "plot_training_curves",
    "runs_cost_limit",
    "write_meta_report",
    "write_report",
]

DEFAULT_COST_LIMIT = 25.0
"""The episode-cost limit of the safety section when none is given (OmniSafe's default)."""

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


def plot_heatmap(table: PayoffTable, path: str | Path, stat: str = "mean", title: str = "") -> Path:
    """Draw protagonists × adversaries, the `stat` true return of each cell, annotated; save it.

    Cells not played are left blank. Returns the path of the PNG (or any matplotlib format).
    """
    plt = _pyplot()
    ps, adv, m = table.matrix(stat)
    if not ps:
        raise ConfigError("The payoff table is empty; evaluate some jobs before plotting it.")
    fig, ax = plt.subplots(figsize=(1.6 + 1.3 * len(adv), 1.2 + 0.6 * len(ps)))
    im = ax.imshow(np.ma.masked_invalid(m), cmap="viridis", aspect="auto")
    ax.set_xticks(range(len(adv)), adv, rotation=30, ha="right")
    ax.set_yticks(range(len(ps)), ps)
    lo, hi = np.nanmin(m), np.nanmax(m)
    for (i, j), v in np.ndenumerate(m):
        if math.isfinite(v):
            dark = hi > lo and (v - lo) / (hi - lo) < 0.5
            ax.text(j, i, f"{v:.4g}", ha="center", va="center", color="w" if dark else "k")
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


def _read_progress(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a progress CSV as float arrays (non-numeric cells become nan)."""

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
        runs[name] = _read_progress(csv_path)
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
    plt = _pyplot()
    fig, axes = plt.subplots(
        len(panels), 1, figsize=(6.5, 2.6 * len(panels)), squeeze=False, layout="constrained"
    )
    for ax, col in zip(axes[:, 0], panels, strict=True):
        for name, cols in runs.items():
            xcol = x or next((k for k in X_COLUMNS if k in cols), None)
            if col in cols and (xcol in cols or xcol is None):
                xs = cols[xcol] if xcol else np.arange(len(cols[col]))
                ax.plot(xs, cols[col], marker=".", label=name)
                ax.set_xlabel(xcol or "row")
        ax.set_ylabel(col)
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
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


def runs_cost_limit(run_dirs: Iterable[str | Path]) -> float | None:
    """The cost limit the runs' constrained learners trained with (the smallest), if any."""
    limits = []
    for d in run_dirs:
        path = Path(d) / "config.json"
        if not path.exists():
            continue
        fix = "Every run writes its config.json when it starts: rerun it, or delete the folder."
        cfg = read_json(path, "run config", fix, kind=dict)
        hparams = cfg.get("protagonist_hparams") or {}
        if "cost_limit" in hparams:
            limits.append(float(hparams["cost_limit"]))
        elif cfg.get("protagonist_algo") in ("ppo-lag", "crpo", "pcrpo"):
            limits.append(DEFAULT_COST_LIMIT)
    return min(limits) if limits else None


def _safety_section(table: PayoffTable, out: Path, limit: float) -> tuple[str, Path]:
    rows = [
        [r["protagonist"], r["adversary"], r["return"], r["cost"], r["cost_ci95"], r["satisfied"]]
        for r in table.safety(limit)
    ]
    header = ["protagonist", "adversary", "return", "episode cost", "cost ±95 %", "satisfied"]
    body = (
        f"True episode cost and constraint satisfaction (share of episodes with cost ≤ "
        f"{limit:g}) beside the true return, under each adversary.\n\n" + _md_table(header, rows)
    )
    return body, plot_safety(table, out / "safety.png", limit)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "–" if math.isnan(v) else f"{v:.4g}"
    return str(v).replace("|", "\\|")


def _md_table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def _how_measured(table: PayoffTable, alpha: float, nominal: str) -> str:
    seeds = sorted({r["seed"] for r in table.rows})
    return (
        f"{len(table)} episodes; seeds {seeds}. Every number is the protagonists' *true* "
        "return (the reward before any reward disruptor) summed over an episode; jobs play "
        "the evaluation phase unless they set `phase`. "
        f"**nominal**: mean in the `{nominal}` column. Over every other column: **mean** of "
        "all episodes; **worst** the lowest cell mean (the worst-case adversary); "
        f"**CVaR** (α = {alpha}) the mean of the ⌈α·n⌉ lowest episode returns; "
        "**degradation** = (nominal − mean) / |nominal|, and **worst deg.** likewise for worst. "
        "± is the half-width of a 95 % Student-t interval over per-seed means."
    )


def write_report(
    out_dir: str | Path,
    title: str,
    table: PayoffTable,
    extra_sections: Mapping[str, str] | None = None,
    figures: Mapping[str, str | Path] | None = None,
    alpha: float = 0.1,
    nominal: str = NOMINAL,
    cost_limit: float | None = None,
) -> Path:
    """Write ``report.md`` (metrics, payoff matrix, figures, method) and the data into `out_dir`.

    Also writes ``payoff.csv``, ``payoff.json`` and ``heatmap.png`` there. `figures` maps
    captions to further image files to link; `extra_sections` maps headings to Markdown.
    When a cost limit is given or any episode had a cost, a safety section (episode cost and
    constraint satisfaction per cell, `DEFAULT_COST_LIMIT` if no limit is given) and
    ``safety.png`` are added. Returns the path of ``report.md``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / "payoff.csv")
    table.to_json(out / "payoff.json")
    figs: dict[str, str | Path] = {"payoff matrix": plot_heatmap(table, out / "heatmap.png")}
    figs.update(figures or {})
    metric_keys = ("nominal", "mean", "worst", "worst_adversary", "cvar", "degradation")
    metric_rows = [
        [m["protagonist"], *(m[k] for k in metric_keys), m["worst_degradation"], m["episodes"]]
        for m in table.metrics(alpha, nominal)
    ]
    header = ["protagonist", "nominal", "mean", "worst", "worst adversary", f"CVaR α={alpha}"]
    header += ["degradation", "worst deg."]
    ps, adv, _ = table.matrix()
    cells = {(c["protagonist"], c["adversary"]): c for c in table.cells()}
    matrix_rows = [[p, *(_cell(cells.get((p, a))) for a in adv)] for p in ps]
    parts = [f"# {title}", "## Robust metrics", _md_table([*header, "episodes"], metric_rows)]
    parts += [
        "## Payoff matrix",
        "Mean true return ± 95 % CI over seeds.",
        _md_table(["", *adv], matrix_rows),
    ]
    if cost_limit is not None or table.has_cost:
        limit = DEFAULT_COST_LIMIT if cost_limit is None else cost_limit
        body, figs["return vs episode cost"] = _safety_section(table, out, limit)
        parts += ["## Safety", body]
    parts += ["## Figures"] + [f"![{c}]({_rel(p, out)})" for c, p in figs.items()]
    parts += ["Data: [payoff.csv](payoff.csv), [payoff.json](payoff.json)."]
    for heading, body in (extra_sections or {}).items():
        parts += [f"## {heading}", body.strip()]
    parts += ["## How this was measured", _how_measured(table, alpha, nominal)]
    path = out / "report.md"
    path.write_text("\n\n".join(parts) + "\n")
    log.info("wrote %s", path)
    return path


def adversary_listing(columns: Mapping[str, Mapping[str, Any]]) -> str:
    """Markdown: which adversaries formed each column (from `advgame.evaluation.columns.describe_column`)."""
    lines = [
        "Each column of the payoff matrix: how its game was made and who played which adversary."
    ]
    for name, desc in columns.items():
        game = ", ".join(f"{k}={v!r}" for k, v in dict(desc.get("game", {})).items()) or "default"
        lines += ["", f"- **{_fmt(name)}** ({game})"]
        advs = desc.get("adversaries", {})
        if isinstance(advs, Mapping):
            lines += [f"  - `{agent}`: `{spec}`" for agent, spec in advs.items()]
        else:
            lines.append(f"  - {advs}")
    return "\n".join(lines)


def _cell(c: Mapping[str, Any] | None) -> str:
    if c is None:
        return "–"
    return f"{c['mean']:.4g}" + ("" if math.isnan(c["ci95"]) else f" ± {c['ci95']:.2g}")


def _rel(path: str | Path, start: Path) -> str:
    try:
        return Path(os.path.relpath(Path(path).resolve(), start.resolve())).as_posix()
    except ValueError:  # another drive (Windows)
        return Path(path).resolve().as_posix()


# -- the meta-game of a population run (advgame.psro) -------------------------------
def meta_game_section(meta: Sequence[Mapping[str, Any]]) -> str:
    """Markdown: per iteration, the meta-game matrix with each side's meta-strategy.

    `meta` is `advgame.psro.load_meta`'s list. Rows are protagonists, columns
    adversaries; a cell is the protagonist's mean true return; the last column and row give
    the protagonists' and the adversaries' meta-strategy probabilities.
    """
    parts = ["## Meta-game", ""]
    for entry in meta:
        advs, prots = entry["adversaries"], entry["protagonists"]
        rows = [
            [p, *[_fmt(v) for v in values], f"{q:.3f}"]
            for p, values, q in zip(
                prots, entry["matrix"], entry["protagonist_strategy"], strict=True
            )
        ]
        rows.append(["adversary strategy", *[f"{q:.3f}" for q in entry["adversary_strategy"]], ""])
        parts += [
            f"### Iteration {entry['iteration']} ({entry['solver']}: value {_fmt(entry['value'])})",
            "",
            _md_table(["protagonist \\ adversary", *advs, "protagonist strategy"], rows),
            "",
        ]
    return "\n".join(parts)


def write_meta_report(run_dir: str | Path) -> Path:
    """Write ``report.md`` of a PSRO run directory (its meta-game section); return its path."""
    from advgame.psro import load_meta

    run_dir = Path(run_dir)
    meta = load_meta(run_dir)
    text = f"# Population training: {run_dir.name}\n\n" + meta_game_section(meta)
    path = run_dir / "report.md"
    path.write_text(text + "\n")
    return path
