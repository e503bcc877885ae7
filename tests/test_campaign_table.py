"""A campaign's tables from its payoff file: the median agent per method and the mean per column."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from advgame.evaluation import ci95
from advgame.reports.campaign import COLUMNS, campaign_table
from advgame.workflows.campaign import load_campaign

SPEC = """
scenario = "Hopper-v5"
methods = ["sac", "rsc"]
seeds = [0, 1, 2]

[train]
iterations = 1
protagonist_steps = 100
eval_episodes = 0

[evaluate]
adversaries = ["preset:ompo-low", "preset:ompo-high"]
seeds = 2
"""

COLUMN_NAMES = ["nominal", "preset ompo-low", "preset ompo-high"]


def _payoff(out: Path, returns: dict[tuple[str, str], list[float]]) -> None:
    """``results/payoff.csv`` with one episode per seed of each (run, column) in `returns`."""
    (out / "results").mkdir(parents=True)
    with (out / "results" / "payoff.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["scenario", "protagonist", "adversary", "seed", "true_return"])
        for (run, column), values in returns.items():
            for seed, value in enumerate(values):
                writer.writerow(["Hopper-v5", run, column, seed, value])


def test_each_method_gets_its_agents_mean_and_interval_in_every_column(tmp_path: Path) -> None:
    spec = tmp_path / "grid.toml"
    spec.write_text(SPEC)
    campaign = load_campaign(spec)
    rng = np.random.default_rng(0)
    runs = ["sac-s0", "sac-s1", "sac-s2", "rsc-s0"]  # rsc-s1, rsc-s2 not evaluated yet
    returns = {(r, c): list(rng.uniform(0, 100, 2)) for r in runs for c in COLUMN_NAMES}
    out = tmp_path / "grid"
    _payoff(out, returns)
    md = campaign_table(campaign, out, out / "finished").read_text()
    section = md.split("## Mean return per column", 1)[1]
    assert "| method | agents | nominal | preset ompo-low | preset ompo-high |" in section
    rows = list(csv.DictReader((out / COLUMNS).open()))
    assert [(r["method"], r["column"]) for r in rows] == [
        (m, c) for m in ("sac", "rsc") for c in COLUMN_NAMES
    ]
    sac_line = next(ln for ln in section.splitlines() if ln.startswith("| sac |"))
    for row in rows:
        agents = [r for r in runs if r.startswith(row["method"] + "-")]
        cells = [float(np.mean(returns[(a, row["column"])])) for a in agents]
        assert int(row["agents"]) == len(agents)
        assert float(row["mean"]) == np.mean(cells)
        if row["method"] == "sac":
            assert float(row["ci95"]) == ci95(cells)
            assert f"| {np.mean(cells):.4g} ± {ci95(cells):.4g} |" in sac_line + " |"
        else:  # one agent: no interval
            assert row["ci95"] == "nan"
    rsc_line = next(ln for ln in section.splitlines() if ln.startswith("| rsc |"))
    assert "±" not in rsc_line and rsc_line.startswith("| rsc | 1 |")


def test_a_column_a_method_never_played_is_a_dash(tmp_path: Path) -> None:
    spec = tmp_path / "grid.toml"
    spec.write_text(SPEC)
    out = tmp_path / "grid"
    returns = {("sac-s0", c): [1.0, 3.0] for c in COLUMN_NAMES}
    returns[("rsc-s0", "nominal")] = [5.0, 7.0]
    _payoff(out, returns)
    md = campaign_table(load_campaign(spec), out, out / "finished").read_text()
    assert "| rsc | 1 | 6 | – | – |" in md
    assert "| sac | 1 | 2 | 2 | 2 |" in md
