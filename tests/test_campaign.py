"""Campaigns: a tiny grid trained in pieces, resumed without redoing finished runs, tabled."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from advgame.campaign import load_campaign
from advgame.cli import main
from advgame.errors import ConfigError

TINY = """
scenario = "Hopper-v5"
methods = ["ppo", "atla"]
seeds = [0, 1]

[train]
iterations = 1
protagonist_steps = 128
adversary_steps = 128
eval_episodes = 0
protagonist_hparams = { n_steps = 64 }
adversary_hparams = { n_steps = 64 }

[evaluate]
adversaries = ["attack:random", "attack:mad"]
seeds = 2
"""


def _stamps(out: Path, runs: list[str]) -> dict[str, int]:
    return {r: (out / "runs" / r / "state.json").stat().st_mtime_ns for r in runs}


def test_a_grid_trains_in_pieces_resumes_and_writes_the_table(tmp_path: Path) -> None:
    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY)
    out = tmp_path / "tiny"
    first = ["campaign", str(spec), "--workers", "1", "--no-progress"]
    assert main([*first, "--stage", "train", "--max-runs", "2"]) == 0
    status = json.loads((out / "status.json").read_text())
    states = {r: s["state"] for r, s in status["runs"].items()}
    assert states == {
        "ppo-s0": "done",
        "ppo-s1": "done",
        "atla-s0": "pending",
        "atla-s1": "pending",
    }
    before = _stamps(out, ["ppo-s0", "ppo-s1"])
    assert main(["campaign", str(spec), "--workers", "2", "--no-progress"]) == 0
    assert _stamps(out, ["ppo-s0", "ppo-s1"]) == before  # finished runs are not trained again
    status = json.loads((out / "status.json").read_text())
    assert all(s["state"] == "done" for s in status["runs"].values())
    assert status["evaluated"] == ["atla-s0", "atla-s1", "ppo-s0", "ppo-s1"]
    table = (out / "campaign.md").read_text()
    assert "| ppo | 2 |" in table and "| atla | 2 |" in table
    lines = (out / "campaign.csv").read_text().splitlines()
    assert lines[0].startswith("method,seeds,median_agent,natural,worst")
    assert len(lines) == 3
    # Once more (same workers, so the same units): nothing is trained or played again.
    parts = {p: p.stat().st_mtime_ns for p in (out / "results" / "parts").iterdir()}
    runs = _stamps(out, list(status["runs"]))
    assert parts
    assert main(["campaign", str(spec), "--workers", "2", "--no-progress"]) == 0
    assert {p: p.stat().st_mtime_ns for p in (out / "results" / "parts").iterdir()} == parts
    assert _stamps(out, list(status["runs"])) == runs


def test_bad_campaign_files_are_clear_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    for text, words in [
        ('methods = ["nope"]\nscenario = "Hopper-v5"', "METHODS"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\n[train]\nbogus = 1', "bogus"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\nseeds = [-1]', "seeds"),
        ("methods = [", "not valid TOML"),
        ('methods = ["ppo"]\nscenario = "Hopper-v5"\nextra = 1', "unknown keys"),
    ]:
        bad.write_text(text)
        with pytest.raises(ConfigError, match=words):
            load_campaign(bad)


def test_the_zoo_campaign_files_load() -> None:
    for path in sorted((Path(__file__).parent.parent / "zoo").glob("*.toml")):
        campaign = load_campaign(path)
        assert campaign.runs()
