"""The learned optimal attack, searched for every kind of protagonist (a checkpoint here)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from advgame.cli import main
from advgame.errors import ConfigError
from advgame.evaluation.attacks.optimal import OPTIMAL_GRID, OptimalSearch


def test_a_checkpoint_gets_its_strongest_searched_adversary(
    pendulum_ppo: Path, tmp_path: Path
) -> None:
    out = tmp_path / "res"
    args = ["evaluate", "--scenario", "InvertedPendulum-v5", "--out", str(out), "--seeds", "2"]
    args += ["--workers", "1", "--budgets", "--adversaries", "nominal", "--exploitability", "256"]
    assert main([*args, "--checkpoint", f"ppo={pendulum_ppo}:ppo", "--raw-obs", "ppo"]) == 0
    search = json.loads((out / "optimal.json").read_text())["ppo"]
    assert len(search["candidates"]) == len(OPTIMAL_GRID)
    kept = [c for c in search["candidates"] if c["kept"]]
    assert len(kept) == 1
    assert kept[0]["selection_return"] == min(c["selection_return"] for c in search["candidates"])
    assert Path(search["kept"]).is_file()
    exploit = json.loads((out / "exploitability.json").read_text())
    assert set(exploit) == {"ppo"}  # not an empty table for a --checkpoint protagonist
    with (out / "payoff.csv").open(newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["adversary"] == "attack optimal"]
    assert len(rows) == 2 and all(r["protagonist"] == "ppo" for r in rows)
    mean = sum(float(r["true_return"]) for r in rows) / 2
    assert exploit["ppo"]["best_response_return"] == pytest.approx(mean)
    assert "## Exploitability" in (out / "report.md").read_text()
    # Run again: the candidates are read back from their part files, not trained again.
    parts = sorted((out / "optimal" / "parts").iterdir())
    stamps = [p.stat().st_mtime_ns for p in parts]
    assert main([*args, "--checkpoint", f"ppo={pendulum_ppo}:ppo", "--raw-obs", "ppo"]) == 0
    assert [p.stat().st_mtime_ns for p in sorted((out / "optimal" / "parts").iterdir())] == stamps


@pytest.mark.parametrize(
    "bad", [{"steps": 0}, {"steps": 10, "grid": ()}, {"steps": 10, "select_seeds": 0}]
)
def test_bad_searches_are_config_errors(bad: dict) -> None:
    with pytest.raises(ConfigError, match="OptimalSearch"):
        OptimalSearch(**bad)
