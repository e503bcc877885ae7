"""The paper's in-training evaluation, the controls in a campaign, and parking outside the tree.

A run with `TrainConfig.eval_conditions` logs each condition's deterministic return at every
iteration (the ``training`` condition at the schedule's current point, presets from their
first episode); a resumed run takes the campaign's evaluation without changing what it
learns; a campaign that gains methods keeps its finished runs and draws the new curves; and a
run parked in ``$ADVGAME_PARK`` resumes in a campaign folder that has no ``parked/``.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import math
from pathlib import Path

import pytest

from advgame.cli import main
from advgame.errors import ConfigError
from advgame.training import TrainConfig, resume, train

pytestmark = pytest.mark.usefixtures("one_torch_thread")

CONDITIONS = ["preset:default", "training"]
SMALL = {
    "scenario": "Hopper-v5",
    "preset": "ompo-nonstationary",
    "protagonist_algo": "sac",
    "learned": [],
    "normalize": False,
    "iterations": 2,
    "protagonist_steps": 60,
    "protagonist_hparams": {"learning_starts": 20, "buffer_size": 1000},
    "task_options": {"max_episode_steps": 20},
}


def _rows(run: Path) -> list[dict[str, str]]:
    return list(csv.DictReader((run / "progress.csv").open()))


@pytest.mark.parametrize(
    ("fields", "match"),
    [({"eval_conditions": ["default"]}, "preset:NAME"), ({"eval_conditions": []}, "non-empty"),
     ({"eval_conditions": ["preset:a", "preset:a"]}, "twice"),
     ({"eval_conditions": ["training"], "eval_episodes": 0}, "eval_episodes >= 1")],
)  # fmt: skip
def test_bad_conditions_are_clear_errors(fields, match) -> None:
    with pytest.raises(ConfigError, match=match):
        TrainConfig(**fields)


def test_a_condition_the_scenario_has_no_preset_for_stops_the_campaign_before_training(
    tmp_path: Path,
) -> None:
    from advgame.workflows.campaign import load_campaign

    spec = tmp_path / "typo.toml"
    spec.write_text(CAMPAIGN.format(methods='["sac"]', episodes=1,
                                    conditions='eval_conditions = ["preset:ompo-nonstatonary"]'))  # fmt: skip
    with pytest.raises(ConfigError, match='Did you mean "ompo-nonstationary"'):
        load_campaign(spec)


def test_each_iteration_logs_every_condition_at_the_schedule_s_current_point(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from advgame.core import episodes

    played: list[tuple[str, list[int | None]]] = []
    real = episodes.rollout_batch

    def spy(games, policies, seeds, indices=None):
        shifted = "dynamics_adversary" in games[0].disruptors
        played.append(("shifted" if shifted else "nominal", list(indices or [])))
        return real(games, policies, seeds, indices)

    monkeypatch.setattr(episodes, "rollout_batch", spy)
    run = tmp_path / "run"
    train(TrainConfig(**SMALL, eval_episodes=2, eval_conditions=CONDITIONS), run, progress=False)
    rows = _rows(run)
    assert len(rows) == 2
    for row in rows:
        assert "eval_nominal_return" not in row  # the conditions replace the nominal pair
        for column in ("eval_default_return", "eval_training_return", "eval_wall_s"):
            assert math.isfinite(float(row[column])) and float(row[column]) > 0
    nominal = [i for name, i in played if name == "nominal"]
    shifted = [i for name, i in played if name == "shifted"]
    assert nominal == [[1], [2]] * 2  # its two episodes, 1 and 2 of the schedule, each point
    # 60 steps of 20-step episodes (or shorter: the hopper falls) per iteration: each point is
    # held at the episode the views play now, later at the second point
    assert len(shifted) == 4 and shifted[0] == shifted[1] and shifted[2] == shifted[3]
    assert 3 <= shifted[0][0] < shifted[2][0]


def test_a_resumed_run_takes_the_evaluation_and_nothing_else(tmp_path: Path) -> None:
    run = tmp_path / "run"
    config = TrainConfig(**{**SMALL, "iterations": 1}, eval_episodes=0)
    train(config, run, progress=False)
    saved = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**saved, "iterations": 2}))
    with pytest.raises(ConfigError, match="change what the run learns"):
        resume(run, progress=False, evaluation={"iterations": 5})
    resume(run, progress=False, evaluation={"eval_episodes": 1, "eval_conditions": CONDITIONS})
    first, second = _rows(run)
    assert first["eval_default_return"] == "" and float(second["eval_default_return"]) > 0
    assert json.loads((run / "config.json").read_text())["eval_conditions"] == CONDITIONS


CAMPAIGN = """
scenario = "Hopper-v5"
methods = {methods}
seeds = [0]

[train]
iterations = 2
protagonist_steps = 60
eval_episodes = {episodes}
{conditions}
protagonist_hparams = {{ learning_starts = 20, buffer_size = 1000 }}
task_options = {{ max_episode_steps = 20 }}
"""


def _digest(folder: Path) -> str:
    files = sorted(p for p in folder.rglob("*") if p.is_file())
    return hashlib.sha256(b"".join(p.read_bytes() for p in files)).hexdigest()


def test_adding_controls_to_a_campaign_keeps_its_finished_runs_and_draws_their_curves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = tmp_path / "grid.toml"
    spec.write_text(CAMPAIGN.format(methods='["sac"]', episodes=0, conditions=""))
    assert main(["campaign", str(spec), "--stage", "train", "--no-progress"]) == 0
    finished = tmp_path / "grid" / "finished" / "sac-s0"
    before = _digest(finished)

    spec.write_text(CAMPAIGN.format(
        methods='["sac", "sac-rsc-matched"]', episodes=1,
        conditions='eval_conditions = ["preset:default"]'))  # fmt: skip
    assert main(["campaign", str(spec), "--status"]) == 0
    out = capsys.readouterr().out
    assert "sac-s0: done (2/2)" in out and "sac-rsc-matched-s0: pending (0/2)" in out
    assert main(["campaign", str(spec), "--stage", "train", "--no-progress"]) == 0
    assert _digest(finished) == before  # a finished run is never trained again
    control = json.loads((tmp_path / "grid/finished/sac-rsc-matched-s0/config.json").read_text())
    hparams = control["protagonist_hparams"]  # the method's settings under the campaign's own
    assert hparams["n_steps"] == 4 and hparams["batch_size"] == 128
    assert hparams["learning_starts"] == 20
    points = list(csv.DictReader((tmp_path / "grid" / "evaluation.csv").open()))
    assert [p["method"] for p in points] == ["sac-rsc-matched"] * 2  # sac has no such points
    assert (tmp_path / "grid" / "evaluation.png").is_file()
    assert main(["campaign", str(spec), "--status"]) == 0
    assert "in-training evaluation curves so far" in capsys.readouterr().out


def test_a_run_parked_in_advgame_park_resumes_where_parked_is_empty(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    from advgame.workflows.campaign import load_campaign

    spec = tmp_path / "tree" / "tiny.toml"
    spec.parent.mkdir()
    spec.write_text(CAMPAIGN.format(methods='["sac"]', episodes=0, conditions=""))
    out = spec.with_suffix("")
    config = load_campaign(spec).config("sac-s0")
    run = out / "runs" / "sac-s0"
    train(dataclasses.replace(config, iterations=1), run, progress=False)  # stopped after 1 of 2
    saved = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**saved, "iterations": 2}))
    elsewhere = tmp_path / "outside"
    monkeypatch.setenv("ADVGAME_PARK", str(elsewhere))
    assert main(["campaign", str(spec), "--park"]) == 0
    assert f"in {elsewhere / 'tiny' / 'sac-s0'}" in capsys.readouterr().out
    assert (elsewhere / "tiny" / "sac-s0" / "state.json").is_file()
    assert not (out / "parked").exists()

    shutil.rmtree(out)  # a fresh checkout: no runs/, no parked/
    assert main(["campaign", str(spec), "--status"]) == 0
    assert "sac-s0: partial (1/2)" in capsys.readouterr().out
    assert main(["campaign", str(spec), "--stage", "train", "--no-progress"]) == 0
    assert [r["iteration"] for r in _rows(out / "finished" / "sac-s0")] == ["1", "2"]
    assert not (elsewhere / "tiny" / "sac-s0").exists()  # a finished run drops its parked copy
