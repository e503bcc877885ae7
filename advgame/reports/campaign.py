"""A campaign's table: ``campaign.md``/``campaign.csv`` and its training curves, from its results.

`campaign_table` is the last step of `advgame.workflows.campaign.run_campaign`; it reads the campaign's
payoff table (``results/payoff.csv``) and its finished runs' progress files, and writes per
method the median agent and the spread over seeds, the mean return in each column of the
table (``campaign_columns.csv``; a cost table in its place for safe campaigns), and
``curves.png`` (each method's mean training curve over its seeds).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from advgame.errors import FileFormatError

__all__ = ["CampaignGrid", "campaign_table", "method_curves"]


class CampaignGrid(Protocol):
    """What the table needs of a campaign (`advgame.workflows.campaign.Campaign` is one)."""

    @property
    def scenario(self) -> str:
        """The scenario id."""
        ...

    @property
    def methods(self) -> Sequence[str]:
        """The methods, in table order."""
        ...

    @property
    def cost_limit(self) -> float | None:
        """The episode cost limit of a safe campaign (None: no cost columns)."""
        ...

    def method_runs(self, method: str) -> list[str]:
        """The runs (``METHOD-sSEED``) of `method`."""
        ...


def campaign_table(campaign: CampaignGrid, out: Path, finished: Path) -> Path:
    """Write ``campaign.md`` and ``campaign.csv`` from the results; return the Markdown path.

    `out` is the campaign's folder (its ``results/``); `finished` holds the finished runs,
    each with its ``progress.csv`` (for the training curves).
    """
    from advgame.evaluation import NOMINAL, PayoffTable, ci95

    path = out / "results" / "payoff.csv"
    if not path.exists():
        raise FileFormatError(f"{path} is missing; evaluate the campaign first.")
    table = PayoffTable.from_csv(path)
    metrics = {m["protagonist"]: m for m in table.metrics(nominal=NOMINAL)}
    rows = []
    for method in campaign.methods:
        agents = [r for r in campaign.method_runs(method) if r in metrics]
        if not agents:
            continue
        nat = np.array([metrics[a]["nominal"] for a in agents])
        worst = np.array([metrics[a]["worst"] for a in agents])
        median = agents[int(np.argsort(worst)[(len(agents) - 1) // 2])]
        rows.append({
            "method": method, "seeds": len(agents), "median_agent": median,
            "natural": metrics[median]["nominal"], "worst": metrics[median]["worst"],
            "worst_attack": metrics[median]["worst_adversary"],
            "natural_iqr": _iqr(nat), "worst_iqr": _iqr(worst),
            "natural_ci95": ci95(nat), "worst_ci95": ci95(worst),
        })  # fmt: skip
    csv_lines = [",".join(rows[0])] + [",".join(str(v) for v in r.values()) for r in rows]
    (out / "campaign.csv").write_text("\n".join(csv_lines) + "\n")
    md = out / "campaign.md"
    text = _table_md(campaign, rows)
    if campaign.cost_limit is not None:
        text += "\n" + _cost_md(campaign, table.safety(campaign.cost_limit))
    else:
        text += "\n" + _columns_md(campaign, table.cells(), out / COLUMNS)
    if _curves(campaign, out, finished) is not None:
        text += (
            f"\n![training curves]({CURVES})\n\n[{CURVES}]({CURVES}): each method's training "
            "return (and episode cost) in its training phases, the mean over its finished runs "
            "(how many in brackets) with their min-max band.\n"
        )
    md.write_text(text)
    return md


COLUMNS = "campaign_columns.csv"
"""Per method and column of the payoff table, the mean return over agents, beside ``campaign.md``."""

CURVES = "curves.png"
"""The campaign's figure of training curves per method, beside ``campaign.md``."""


def _curves(campaign: CampaignGrid, out: Path, finished: Path) -> Path | None:
    """Write ``curves.png``: return (and cost, for safe campaigns) over steps, per method."""
    files = {
        r: finished / r / "progress.csv" for m in campaign.methods for r in campaign.method_runs(m)
    }
    return method_curves(campaign, files, out / CURVES, title=f"{campaign.scenario}: {out.name}")


def method_curves(
    campaign: CampaignGrid,
    files: Mapping[str, Path],
    path: Path,
    ragged: bool = False,
    title: str = "",
    columns: Sequence[str] | None = None,
) -> Path | None:
    """Draw each method's training return (and cost, for safe campaigns) over steps; save it.

    `files` maps runs (``METHOD-sSEED``) to their ``progress.csv``; a method's line is the mean
    over its runs, its band their minimum and maximum. Runs are cut to the shortest one's
    points, or with `ragged` (runs still in training) each point is over the runs that have
    reached it (`advgame.reports.plots.plot_method_curves`); `title` heads the figure;
    `columns` draws those ``progress.csv`` columns instead (the in-training evaluation's). None
    when nothing is drawn.
    """
    from advgame.reports.plots import plot_method_curves

    groups = {
        m: [files[r] for r in campaign.method_runs(m) if r in files] for m in campaign.methods
    }
    if columns is not None:
        return plot_method_curves(groups, path, list(columns), ragged=ragged, title=title)
    columns = ["protagonist_phase_true_return"]
    lines = {}
    if campaign.cost_limit is not None:
        columns.append("protagonist_phase_true_cost")
        lines["protagonist_phase_true_cost"] = float(campaign.cost_limit)
    return plot_method_curves(groups, path, columns, lines=lines, ragged=ragged, title=title)


def _cost_md(campaign: CampaignGrid, cells: list[dict[str, Any]]) -> str:
    """Per method and column: return and episode cost over seeds, and the satisfaction rate."""
    from advgame.evaluation import ci95

    lines = [
        f"## Cost (limit {campaign.cost_limit:g} per episode)",
        "",
        "| method | column | seeds | return | ±95 % | episode cost | ±95 % | cost ≤ limit |",
        "|" + "---|" * 8,
    ]
    for method, mine in _method_cells(campaign, cells):
        for column in dict.fromkeys(c["adversary"] for c in mine):
            sel = [c for c in mine if c["adversary"] == column]
            ret = [c["return"] for c in sel]
            cost = [c["cost"] for c in sel]
            episodes = sum(c["episodes"] for c in sel)
            ok = sum(c["satisfied"] * c["episodes"] for c in sel) / episodes
            cells_ = [method, column, len(sel), float(np.mean(ret)), ci95(ret),
                      float(np.mean(cost)), ci95(cost), f"{100 * ok:.0f} %"]  # fmt: skip
            lines.append(_row(cells_))
    lines += [
        "",
        "Return and episode cost are the means over the method's agents of each agent's mean "
        "over its evaluation episodes (true reward, true cost); ±95 % is the Student-t "
        "half-width over agents; cost ≤ limit is the share of all the method's evaluation "
        "episodes within the limit.",
    ]
    return "\n".join(lines) + "\n"


def _method_cells(
    campaign: CampaignGrid, cells: list[dict[str, Any]]
) -> Iterator[tuple[str, list[dict[str, Any]]]]:
    """Each method, in table order, with the cells of its agents (`cells`' order)."""
    for method in campaign.methods:
        runs = set(campaign.method_runs(method))
        yield method, [c for c in cells if c["protagonist"] in runs]


def _columns_md(campaign: CampaignGrid, cells: list[dict[str, Any]], path: Path) -> str:
    """Per method (a row) and column of the payoff table: the mean return over its agents.

    Each agent's cell is the mean of its evaluation episodes; a method's entry is the mean of
    its agents' cells with the Student-t 95 % half-width over them. Also written long-form to
    `path` (method, column, agents, mean, ci95).
    """
    from advgame.evaluation import ci95

    columns = list(dict.fromkeys(c["adversary"] for c in cells))
    lines = [
        "## Mean return per column",
        "",
        "| method | agents | " + " | ".join(columns) + " |",
        "|" + "---|" * (len(columns) + 2),
    ]
    rows: list[list[Any]] = [["method", "column", "agents", "mean", "ci95"]]
    for method, mine in _method_cells(campaign, cells):
        if not mine:
            continue
        entries = []
        for column in columns:
            means = [c["mean"] for c in mine if c["adversary"] == column]
            if not means:
                entries.append("–")
                continue
            mean, half = float(np.mean(means)), ci95(means)
            entries.append(_fmt(mean) if math.isnan(half) else f"{_fmt(mean)} ± {_fmt(half)}")
            rows.append([method, column, len(means), mean, half])
        agents = len({c["protagonist"] for c in mine})
        lines.append(_row([method, agents, *entries]))
    lines += [
        "",
        "Each entry is the mean over the method's agents of each agent's mean true return over "
        "its evaluation episodes, ± the Student-t 95 % half-width over agents (none for "
        f"one agent). Data: [{path.name}]({path.name}).",
    ]
    with path.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    return "\n".join(lines) + "\n"


def _iqr(values: np.ndarray) -> str:
    q1, q3 = np.percentile(values, [25, 75])
    return f"{q1:.4g}–{q3:.4g}"


def _fmt(v: Any) -> str:
    return (
        f"{v:.4g}"
        if isinstance(v, float) and not math.isnan(v)
        else ("–" if isinstance(v, float) else str(v))
    )


def _row(cells: list[Any]) -> str:
    """One Markdown table row of `cells`, numbers to four significant digits."""
    return "| " + " | ".join(_fmt(c) for c in cells) + " |"


def _table_md(campaign: CampaignGrid, rows: list[dict[str, Any]]) -> str:
    head = "| method | seeds | median agent | natural | IQR | ±95 % | worst adversary | worst | IQR | ±95 % |"
    lines = [f"# Campaign: {campaign.scenario}", "", head, "|" + "---|" * 10]
    for r in rows:
        cells = [r["method"], r["seeds"], r["median_agent"], r["natural"], r["natural_iqr"],
                 r["natural_ci95"], r["worst_attack"], r["worst"], r["worst_iqr"], r["worst_ci95"]]  # fmt: skip
        lines.append(_row(cells))
    lines += [
        "",
        "The median agent of a method is its run with the median worst-of-adversaries return "
        "(the lowest mean true return over the table's adversary columns: attacks and "
        "presets alike); natural and worst are that agent's nominal and worst returns, "
        "worst adversary the column of its worst. IQR and ±95 % (Student t) are over the "
        "method's seeds, so the median agent's natural return can lie outside its IQR. Data: "
        "[results/payoff.csv](results/payoff.csv), the full report: "
        "[results/report.md](results/report.md).",
    ]
    return "\n".join(lines) + "\n"
