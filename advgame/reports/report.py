"""The Markdown report of a robust evaluation (a `PayoffTable`), with its figures.

The figures are drawn by `advgame.reports.plots` (re-exported here)::

    table = evaluate(jobs, workers=2)
    write_report("out", "Hopper robustness", table)  # -> out/report.md, heatmap.png, ...
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from advgame.core.files import read_json
from advgame.evaluation import NOMINAL, PayoffTable
from advgame.reports.plots import (
    plot_budget_curve,
    plot_heatmap,
    plot_safety,
    plot_training_curves,
)
from advgame.training.config import SAFE_ALGOS

__all__ = [
    "DEFAULT_COST_LIMIT",
    "adversary_listing",
    "exploitability_md",
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
        elif cfg.get("protagonist_algo") in SAFE_ALGOS:
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
    na = table.not_applicable
    matrix_rows = [
        [p, *("n/a" if (p, a) in na else _cell(cells.get((p, a))) for a in adv)] for p in ps
    ]
    parts = [f"# {title}", "## Robust metrics", _md_table([*header, "episodes"], metric_rows)]
    parts += [
        "## Payoff matrix",
        "Mean true return ± 95 % CI over seeds" + ("; n/a: not applicable." if na else "."),
        _md_table(["", *adv], matrix_rows),
    ]
    if na:
        parts += ["## Cells not applicable", not_applicable_md(na)]
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


def not_applicable_md(na: Mapping[tuple[str, str], str]) -> str:
    """Markdown: the cells that were not played, with each column's reason."""
    lines = [
        "These cells were not played: their column cannot play that protagonist. They are "
        "left out of every metric above (mean, worst, CVaR, degradation).",
        "",
    ]
    lines += [f"- **{_fmt(p)}** × **{_fmt(a)}**: {_fmt(why)}" for (p, a), why in na.items()]
    return "\n".join(lines)


def adversary_listing(columns: Mapping[str, Mapping[str, Any]]) -> str:
    """Markdown: which adversaries formed each column (from `advgame.evaluation.table.columns.describe_column`)."""
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


# -- the meta-game of a population run (advgame.workflows.psro) -------------------------------
def meta_game_section(meta: Sequence[Mapping[str, Any]]) -> str:
    """Markdown: per iteration, the meta-game matrix with each side's meta-strategy.

    `meta` is `advgame.workflows.psro.load_meta`'s list. Rows are protagonists, columns
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


def write_meta_report(run_dir: str | Path, meta: Sequence[Mapping[str, Any]]) -> Path:
    """Write ``report.md`` of a PSRO run directory from its meta-game; return its path.

    `meta` is the run's meta-game (`advgame.workflows.psro.load_meta`).
    """
    run_dir = Path(run_dir)
    text = f"# Population training: {run_dir.name}\n\n" + meta_game_section(meta)
    path = run_dir / "report.md"
    path.write_text(text + "\n")
    return path


def exploitability_md(results: Mapping[str, Mapping[str, Any]]) -> str:
    """The report's Exploitability section from ``exploitability.json``."""
    lines = [
        "Return under best-response adversaries trained against each frozen protagonist "
        "within the threat model's budget (the same preset for every protagonist).",
        "",
        "| protagonist | preset | nominal | best response | exploitability | steps |",
        "|---|---|---|---|---|---|",
    ]
    for name, r in results.items():
        lines.append(
            f"| {name} | {r['preset']} | {r['nominal_return']:.4g} | "
            f"{r['best_response_return']:.4g} | {r['exploitability']:.4g} | "
            f"{int(r['best_response_steps'])} |"
        )
    return "\n".join(lines)
