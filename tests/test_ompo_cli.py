"""OMPO from the command line: it trains on OMPO's shifting Hopper, resumes, and is evaluated."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from advgame.cli import main

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = {
    "learning_starts": 100, "batch_size": 32, "net_arch": [32, 32], "local_size": 100,
    "disc_batch": 32,
}  # fmt: skip


def _args(run: Path, scenario: str = "Hopper-v5", preset: str = "ompo-nonstationary") -> list[str]:
    return [
        "train", "--method", "ompo", "--scenario", scenario, "--preset", preset,
        "--iterations", "1", "--protagonist-steps", "300", "--eval-episodes", "1",
        "--set", f"protagonist_hparams={json.dumps(TINY)}", "--no-progress",
        "--run-dir", str(run),
    ]  # fmt: skip


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_ompo_trains_on_the_shifting_hopper_resumes_and_evaluates(tmp_path: Path) -> None:
    from advgame.agents.ompo.ompo import OMPO

    run = tmp_path / "ompo"
    assert main(_args(run)) == 0
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["protagonist_algo"] == "ompo" and cfg["normalize"] is False
    first = OMPO.load(run / "checkpoints" / "iter_0001" / "protagonist.zip", device="cpu")
    assert first.counts["critic"] == 3 * (300 - 100) and first.counts["discriminator"] > 0
    cfg["iterations"] = 2
    (run / "config.json").write_text(json.dumps(cfg))
    assert main(["resume", str(run), "--no-progress"]) == 0
    second = OMPO.load(run / "checkpoints" / "iter_0002" / "protagonist.zip", device="cpu")
    assert second.counts["critic"] == 3 * (600 - 100)  # the update count carried on
    # The shifting task went on where it stopped: the first run played episodes 1 .. 1 + e1
    # (e1 finished, the last cut off); the resumed one starts at the next and plays e2 more.
    finished = [int(r["protagonist_phase_episodes"]) for r in _rows(run / "progress.csv")]
    at = [
        json.loads(
            (run / "checkpoints" / f"iter_000{i}" / "protagonist_schedules.json").read_text()
        )
        for i in (1, 2)
    ]
    assert at[0] == [{"dynamics_adversary": 1 + finished[0]}]
    assert at[1] == [{"dynamics_adversary": at[0][0]["dynamics_adversary"] + 1 + finished[1]}]
    # only the latest checkpoint keeps its (large) replay buffer: a resume needs no other
    assert not (run / "checkpoints" / "iter_0001" / "protagonist_replay.pkl").exists()
    assert (run / "checkpoints" / "iter_0002" / "protagonist_replay.pkl").exists()
    out = tmp_path / "eval"
    model = run / "checkpoints" / "iter_0002" / "protagonist.zip"
    code = main([
        "evaluate", "--scenario", "Hopper-v5", "--checkpoint", f"ompo={model}:ompo",
        "--adversaries", "nominal", "preset:ompo-nonstationary", "--seeds", "2",
        "--raw-obs", "ompo", "--out", str(out),
    ])  # fmt: skip
    assert code == 0
    table = json.loads((out / "payoff.json").read_text())
    assert "ompo" in json.dumps(table) and "ompo-nonstationary" in json.dumps(table)


@pytest.mark.parametrize(
    ("scenario", "preset", "says"),
    [("LunarLander-v3", "default", "continuous"), ("MA-Ant-2x4", "default", "ompo")],
)
def test_ompo_refuses_what_it_cannot_serve_before_training(
    tmp_path: Path, capsys, scenario: str, preset: str, says: str
) -> None:
    assert main(_args(tmp_path / "run", scenario, preset)) == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err
    assert not (tmp_path / "run" / "checkpoints" / "iter_0001").exists()
