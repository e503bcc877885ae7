"""Tables that mix controllers and networks: cells a column cannot play are checked before any
job runs, recorded as not applicable with the reason, shown as "n/a" and left out of metrics."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from advgame.cli import main
from advgame.evaluation import (
    AdversarySetup,
    PayoffTable,
    evaluate,
    not_applicable,
    population_jobs,
    sb3_protagonist,
)


def still(obs: np.ndarray) -> np.ndarray:
    """A fixed controller: no torque (InvertedPendulum has one action)."""
    return np.zeros(1, dtype=np.float32)


@pytest.fixture
def model(pendulum_ppo: Path) -> Path:
    """The session's small PPO on InvertedPendulum-v5 (`pendulum_ppo`)."""
    return pendulum_ppo


def _setups() -> dict[str, AdversarySetup]:
    from advgame.adversaries import MADAttack

    mad = AdversarySetup({"preset": "default"}, {"observation_adversary": MADAttack(steps=2)})
    return {"nominal": AdversarySetup.nominal(), "attack mad": mad}


def test_an_attack_cannot_play_a_controller_and_says_why(model: Path) -> None:
    prots = {"still": still, "ppo": sb3_protagonist(model, raw_observations=True)}
    jobs = population_jobs("InvertedPendulum-v5", prots, _setups(), seeds=(0,))
    na = not_applicable(jobs)
    assert set(na) == {("still", "attack mad")}
    assert "white-box access" in na[("still", "attack mad")]


class _Learns:
    """A column that learns per victim (as PA-AD does) and may refuse a row; never played."""

    def build(self, info: object) -> object:
        raise AssertionError("the checks only ask; they never build the adversary")

    def learned(self, game: object, agent: str, victims: dict) -> bool:
        return True  # already cached: learn_ahead queues nothing

    def learn(self, game: object, agent: str, victims: dict) -> None:
        raise AssertionError("learned() said there is nothing to learn")

    def unplayable(self, game: object, agent: str, victims: dict) -> str | None:
        return None


def test_both_checks_build_each_row_once(model: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from advgame.evaluation.table import applicable

    built: list[object] = []
    real = applicable._protagonists
    monkeypatch.setattr(applicable, "_protagonists", lambda g, s: built.append(s) or real(g, s))
    setups = {
        f"learns {i}": AdversarySetup({"preset": "default"}, {"observation_adversary": _Learns()})
        for i in range(3)
    }
    prots = {"still": still, "ppo": sb3_protagonist(model, raw_observations=True)}
    jobs = population_jobs("InvertedPendulum-v5", prots, setups, seeds=(0,))
    with applicable.Rows() as rows:
        assert applicable.learn_ahead(jobs, workers=2, executor="local", rows=rows) == 0
        assert applicable.not_applicable(jobs, rows) == {}
    assert len(built) == 2  # one build per row, not per column nor per check


def test_evaluate_plays_the_other_cells_and_records_the_reason(model: Path) -> None:
    prots = {"still": still, "ppo": sb3_protagonist(model, raw_observations=True)}
    jobs = population_jobs("InvertedPendulum-v5", prots, _setups(), seeds=(0, 1))
    table = evaluate(jobs, progress=False)
    assert {(r["protagonist"], r["adversary"]) for r in table.rows} == {
        ("still", "nominal"),
        ("ppo", "nominal"),
        ("ppo", "attack mad"),
    }
    assert list(table.not_applicable) == [("still", "attack mad")]
    ps, adv, m = table.matrix()
    assert math.isnan(m[ps.index("still"), adv.index("attack mad")])
    metrics = {row["protagonist"]: row for row in table.metrics()}
    assert metrics["still"]["not_applicable"] == 1 and metrics["still"]["adversaries"] == 0
    assert math.isnan(metrics["still"]["worst"])  # no column left: no worst case, not a zero
    assert metrics["ppo"]["not_applicable"] == 0 and metrics["ppo"]["adversaries"] == 1


def test_the_reason_survives_csv_and_json(tmp_path: Path) -> None:
    rows = [{"protagonist": "p", "adversary": "nominal", "seed": 0, "true_return": 1.0}]
    table = PayoffTable(rows, {("c", "attack mad"): "needs white-box access"})
    for back in (
        PayoffTable.from_csv(table.to_csv(tmp_path / "t.csv")),
        PayoffTable.from_json(table.to_json(tmp_path / "t.json")),
    ):
        assert back.not_applicable == table.not_applicable
        assert back.rows == table.rows
        assert back.protagonists == ["p", "c"] and back.adversaries == ["nominal", "attack mad"]


def test_the_cli_writes_a_complete_report_with_na_cells(model: Path, tmp_path: Path) -> None:
    out = tmp_path / "res"
    args = ["evaluate", "--scenario", "InvertedPendulum-v5", "--out", str(out), "--seeds", "1"]
    args += ["--workers", "1", "--budgets", "--threat", "default"]
    args += ["--checkpoint", f"ppo={model}:ppo", "--raw-obs", "ppo"]
    args += ["--callable", f"still={__name__}:still", "--adversaries", "nominal", "attack:mad"]
    assert main(args) == 0
    with (out / "payoff.csv").open(newline="") as f:
        na = [r for r in csv.DictReader(f) if r["not_applicable"]]
    assert [(r["protagonist"], r["adversary"]) for r in na] == [("still", "attack mad")]
    report = (out / "report.md").read_text()
    assert "## Cells not applicable" in report and "white-box access" in report
    assert "| still | " in report and "n/a" in report.split("## Payoff matrix")[1]
    assert (out / "heatmap.png").stat().st_size > 0
