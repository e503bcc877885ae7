"""One threat model per table, and the worst-of-attacks suite: protagonists trained under
different presets are attacked, replayed against learned adversaries and best-responded in the
same disruptors and budgets, and the report says which attack was worst."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from advgame.cli import main
from advgame.errors import ConfigError, UnknownNameError
from advgame.evaluation.table.columns import adversary_columns, default_threat

TINY = [
    "--scenario", "Hopper-v5", "--iterations", "1", "--protagonist-steps", "64",
    "--adversary-steps", "64", "--set", 'protagonist_hparams={"n_steps": 64}',
    "--set", 'adversary_hparams={"n_steps": 64}', "--no-progress",
]  # fmt: skip


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """PPO (trained in preset 'default', no adversary) and ATLA-PPO (trained in 'atla')."""
    folder = tmp_path_factory.mktemp("runs")
    for method in ("ppo", "atla"):
        assert main(["train", "--method", method, *TINY, "--run-dir", str(folder / method)]) == 0
    return folder / "ppo", folder / "atla"


@pytest.mark.usefixtures("one_torch_thread")
def test_every_row_faces_one_threat_model_and_the_worst_attack_is_named(
    two_runs: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from functools import partial

    from advgame.evaluation.attacks.optimal import OPTIMAL_GRID, OptimalSearch
    from advgame.workflows import suite

    # Budget: the optimal attack searches one candidate, not the whole grid (each trains a
    # 2048-step rollout whatever --exploitability says); tests/test_optimal.py searches the grid.
    monkeypatch.setattr(suite, "OptimalSearch", partial(OptimalSearch, grid=OPTIMAL_GRID[:1]))
    ppo, atla = two_runs
    assert json.loads((ppo / "config.json").read_text())["preset"] != "atla"  # unlike trainings
    out = tmp_path / "results"
    args = ["evaluate", str(ppo), str(atla), "--out", str(out), "--seeds", "1", "--budgets"]
    args += ["--adversaries", "attacks,samples=500,epochs=2", "--exploitability", "64"]
    args += ["--workers", "1"]
    assert main(args) == 0
    threat = json.loads((out / "threat.json").read_text())
    assert threat["preset"] == default_threat("Hopper-v5") == "atla"
    columns = json.loads((out / "columns.json").read_text())
    assert set(columns) == {
        "nominal",
        "attack random",
        "attack mad",
        "attack critic",
        "attack rs",
        "attack optimal",
        "learned (atla)",
    }
    for name, column in columns.items():
        if name != "nominal":  # attacks and the learned adversary all play in the threat model
            assert column["game"] == {"preset": "atla"}, (name, column)
    exploit = json.loads((out / "exploitability.json").read_text())
    assert {r["preset"] for r in exploit.values()} == {"atla"}  # not each run's own preset
    with (out / "payoff.csv").open(newline="") as f:
        cells = {(r["protagonist"], r["adversary"]) for r in csv.DictReader(f)}
    assert cells == {(p, c) for p in ("ppo", "atla") for c in columns}
    report = (out / "report.md").read_text()
    assert "## Threat model" in report and "Preset `atla`" in report
    assert "worst adversary" in report


def test_an_explicit_threat_model_moves_every_attack_column(two_runs: tuple[Path, Path]) -> None:
    _, atla = two_runs
    cols = adversary_columns(
        "Hopper-v5", ["attack:mad", "attack:random"], threat="obs-normalized-0.1"
    )
    assert {c.make_kwargs["preset"] for n, c in cols.items() if n != "nominal"} == {
        "obs-normalized-0.1"
    }
    # a learned observation adversary replays in another observation budget
    cols = adversary_columns("Hopper-v5", [f"learned:{atla}"], threat="default")
    assert cols["learned (atla)"].make_kwargs == {"preset": "default"}


def test_bad_threat_models_are_clear_errors(two_runs: tuple[Path, Path]) -> None:
    _, atla = two_runs
    with pytest.raises(UnknownNameError, match="Did you mean"):
        adversary_columns("Hopper-v5", ["attack:mda"])
    with pytest.raises(ConfigError, match="no bounded observation disruptor"):
        adversary_columns("Hopper-v5", ["attack:mad"], threat="rarl")
    with pytest.raises(ConfigError, match="has no such agent"):
        adversary_columns("Hopper-v5", [f"learned:{atla}"], threat="rarl")


@pytest.mark.usefixtures("one_torch_thread")
def test_a_table_of_presets_only_names_no_threat_model(
    two_runs: tuple[Path, Path], tmp_path: Path
) -> None:
    ppo, _ = two_runs
    out = tmp_path / "results"
    out.mkdir()
    (out / "threat.json").write_text("{}")  # left by an earlier table of this folder
    args = ["evaluate", str(ppo), "--out", str(out), "--seeds", "1", "--budgets", "--workers", "1"]
    assert main([*args, "--adversaries", "preset:rarl"]) == 0
    assert not (out / "threat.json").exists()  # the table's columns do not play the atla preset
    assert "## Threat model" not in (out / "report.md").read_text()
    assert main([*args, "--adversaries", "preset:rarl", "--threat", "rarl"]) == 0
    assert json.loads((out / "threat.json").read_text())["preset"] == "rarl"  # a column plays it
