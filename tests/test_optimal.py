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
    pendulum_ppo: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "res"
    args = ["evaluate", "--scenario", "InvertedPendulum-v5", "--out", str(out), "--seeds", "2"]
    args += ["--workers", "1", "--budgets", "--adversaries", "nominal", "--exploitability", "256"]
    assert main([*args, "--checkpoint", f"ppo={pendulum_ppo}:ppo", "--raw-obs", "ppo"]) == 0
    search = json.loads((out / "optimal.json").read_text())["ppo"]
    # progress (stderr is a file here): a line as the search starts and one per candidate
    err = capsys.readouterr().err
    n = len(search["candidates"])
    assert "optimal attack InvertedPendulum-v5: 0/" in err
    assert f"; {n} candidates to train, 0 read back" in err
    assert err.count("optimal attack InvertedPendulum-v5:") == n + 1
    assert f"; {n} this run)" in err
    # a feed-forward protagonist: every entry but the LSTM adversary (recurrent victims only)
    offered = [dict(g) for g in OPTIMAL_GRID if g.get("victims", "all") == "all"]
    assert len(offered) == len(OPTIMAL_GRID) - 1
    assert [c["hparams"] for c in search["candidates"]] == offered
    # the search's own keys reach the trainer: 4 views for the SB3 recipe, 5x the steps for the
    # long candidate; the others train one view for --exploitability steps
    from stable_baselines3 import PPO

    def trained(k: int) -> tuple[int, int]:
        (zip_path,) = (out / "optimal" / "ppo" / str(k)).glob("*.zip")
        model = PPO.load(zip_path, device="cpu")
        return model.n_envs, model.num_timesteps

    long_k = next(k for k, g in enumerate(OPTIMAL_GRID) if g.get("steps_scale", 1) > 1)
    assert trained(0) == (1, 2048)  # one rollout of n_steps 2048 covers 256 steps
    assert trained(long_k)[0] == 4

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
    assert f"(100 %), 0 s; 0 candidates to train, {n} read back" in capsys.readouterr().err
    # ...and so are the candidates' selection cells: no episode played, the same one kept
    selection = out / "optimal" / "selection"
    assert len(list((selection / "parts").glob("*.pkl"))) == n
    timings = [json.loads(ln) for ln in (selection / "jobs.jsonl").read_text().splitlines()]
    assert len(timings) == n and all(t["attempts"] == 0 for t in timings)
    assert json.loads((out / "optimal.json").read_text())["ppo"] == search


def test_the_long_candidate_trains_first_with_its_scaled_budget(
    pendulum_ppo: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from advgame.agents.common.checkpoint import SB3Checkpoint
    from advgame.evaluation.attacks.optimal import _search
    from advgame.evaluation.table.threat import default_threat, observation_agent

    units: list = []

    def capture(fn: object, jobs: list, **kwargs: object) -> None:
        units.extend(jobs)
        raise RuntimeError("captured")

    monkeypatch.setattr("advgame.runner.run.run_units", capture)
    threat = default_threat("InvertedPendulum-v5")
    agent = observation_agent("InvertedPendulum-v5", threat)
    victim = {"ppo": SB3Checkpoint(str(pendulum_ppo), "ppo", None)}
    with pytest.raises(RuntimeError, match="captured"):
        _search("InvertedPendulum-v5", threat, agent, victim, OptimalSearch(steps=1000), tmp_path)
    scales = [g.get("steps_scale", 1) for g in OPTIMAL_GRID if "victims" not in g]
    assert [u.steps for u in units] == sorted((1000 * s for s in scales), reverse=True)
    assert units[0].hparams["n_envs"] == 4 and "steps_scale" not in units[0].hparams
    assert all(u.algo == "ppo" and not {"algo", "victims"} & set(u.hparams) for u in units)
    assert units[0].name == f"ppo/{scales.index(max(scales))}"  # its index, not its position


@pytest.mark.parametrize(
    "bad",
    [
        {"steps": 0},
        {"steps": 10, "grid": ()},
        {"steps": 10, "select_seeds": 0},
        {"steps": 10, "grid": ({"algo": "sac"},)},
        {"steps": 10, "grid": ({"victims": "lstm"},)},
    ],
)
def test_bad_searches_are_config_errors(bad: dict) -> None:
    with pytest.raises(ConfigError, match="OptimalSearch"):
        OptimalSearch(**bad)
