"""A run's game from its config: its own disruptors and task options, and fixed adversaries
(noise, white-box, LLM) named by specs, recorded in the run directory and resumed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from advgame.adversaries import GaussianAdversary, UniformAdversary
from advgame.adversaries.specs import adversary_spec
from advgame.cli import main
from advgame.errors import ConfigError, UnknownNameError
from advgame.training import TrainConfig

TINY = {
    "scenario": "Hopper-v5",
    "iterations": 1,
    "protagonist_steps": 128,
    "adversary_steps": 128,
    "eval_episodes": 1,
    "protagonist_hparams": {"n_steps": 64},
    "adversary_hparams": {"n_steps": 64},
    "learned": None,
    "disruptors": {"observation": {"eps": 0.05}, "action": {"eps": 0.1}},
    "task_options": {"max_episode_steps": 3},
    "adversaries": {"action_adversary": "gauss:0.1"},
}


def test_a_config_file_with_its_own_game_trains_and_resumes(tmp_path: Path) -> None:
    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps(TINY))
    run = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--run-dir", str(run), "--no-progress"]) == 0
    saved = json.loads((run / "config.json").read_text())
    assert saved["adversaries"] == {"action_adversary": "gauss:0.1"}
    assert saved["task_options"] == {"max_episode_steps": 3}
    members = json.loads((run / "population.json").read_text())
    assert {m["agent"] for m in members} == {
        "observation_adversary"
    }  # the fixed one is not learned
    header, row = (run / "progress.csv").read_text().splitlines()[:2]
    episodes = float(row.split(",")[header.split(",").index("protagonist_phase_episodes")])
    assert episodes >= 128 // 3  # every episode is cut at the run's own 3-step limit
    saved["iterations"] = 2  # a user extends the run: resume continues with the same game
    (run / "config.json").write_text(json.dumps(saved))
    assert main(["resume", str(run), "--no-progress"]) == 0
    assert json.loads((run / "state.json").read_text())["iteration"] == 2


def test_adversary_options_on_the_command_line(tmp_path: Path) -> None:
    from advgame.cli.app import _train_config, build_parser

    args = build_parser().parse_args(
        ["train", "--method", "atla", "--adversary", "observation_adversary=uniform:0.02",
         "--adversary", 'action_adversary={"kind": "gauss", "std": 0.3}']
    )  # fmt: skip
    cfg = _train_config(args)
    fixed = cfg.fixed_adversaries()
    assert fixed["observation_adversary"] == UniformAdversary(low=-0.02, high=0.02)
    assert fixed["action_adversary"] == GaussianAdversary(std=0.3)
    bad = build_parser().parse_args(["train", "--adversary", "nothing"])
    with pytest.raises(ConfigError, match="AGENT=SPEC"):
        _train_config(bad)


@pytest.mark.parametrize(
    ("spec", "error", "words"),
    [
        ("gaus:0.1", UnknownNameError, "Did you mean"),
        ("gauss:big", ConfigError, "not a number"),
        ("mad:3", ConfigError, "takes no argument"),
        ({"kind": "uniform", "width": 1}, ConfigError, "width"),
        (3, ConfigError, "text"),
    ],
)
def test_bad_adversary_specs_name_the_fix(spec: object, error: type, words: str) -> None:
    with pytest.raises(error, match=words):
        adversary_spec(spec)  # type: ignore[arg-type]
    with pytest.raises(error, match=words):
        TrainConfig(adversaries={"observation_adversary": spec})


def test_a_white_box_attack_on_the_learner_is_a_clear_error(tmp_path: Path) -> None:
    cfg = TrainConfig(**{**TINY, "adversaries": {"observation_adversary": "mad"}})
    from advgame.training import train

    with pytest.raises(ConfigError, match="white-box"):
        train(cfg, tmp_path / "run", progress=False)
