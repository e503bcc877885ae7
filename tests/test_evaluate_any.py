"""Evaluating any fixed policy (a plain SB3 model + `VecNormalize`, callables, runs) against
chosen adversary columns, from the CLI and `advgame.evaluation`; results folders that move."""

from __future__ import annotations

import csv
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from advgame.cli import main
from advgame.errors import ConfigError, UnknownNameError
from advgame.evaluation import (
    SEED_STRIDE,
    AdversarySetup,
    adversary_columns,
    check_protagonists,
    sb3_protagonist,
)
from advgame.training.population import Population


def rows(folder: Path) -> list[dict[str, str]]:
    with (folder / "payoff.csv").open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def plain_sb3(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """PPO + VecNormalize trained with plain SB3 on Gymnasium's Hopper-v5, saved elsewhere."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp("elsewhere")
    venv = VecNormalize(DummyVecEnv([lambda: gym.make("Hopper-v5")]), gamma=0.99)
    venv.seed(0)
    model = PPO("MlpPolicy", venv, n_steps=512, batch_size=64, n_epochs=2, seed=0, device="cpu")
    model.learn(2048)
    model.save(folder / "model.zip")
    venv.save(str(folder / "vecnormalize.pkl"))
    venv.close()
    return folder


def plain_returns(folder: Path, seeds: list[int]) -> list[float]:
    """The same episodes played with plain SB3 + Gymnasium code: deterministic actions."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    model = PPO.load(folder / "model.zip", device="cpu")
    norm = VecNormalize.load(
        str(folder / "vecnormalize.pkl"), DummyVecEnv([lambda: gym.make("Hopper-v5")])
    )
    norm.training = False
    env = gym.make("Hopper-v5")
    out = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(norm.normalize_obs(obs), deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            done = terminated or truncated
        out.append(total)
    env.close()
    return out


@pytest.fixture(scope="module")
def atla_run(tmp_path_factory: pytest.TempPathFactory, tiny_atla: Callable[..., list[str]]) -> Path:
    """A tiny `advgame train --method atla` run: snapshots @0, @1, @2 of its adversary."""
    run = tmp_path_factory.mktemp("runs") / "atla"
    assert main(["train", *tiny_atla(), "--run-dir", str(run)]) == 0
    return run


def test_a_plain_sb3_model_plays_the_nominal_episodes_plain_sb3_plays(
    plain_sb3: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    args = ["evaluate", "--scenario", "Hopper-v5", "--out", "results", "--seeds", "2"]
    args += ["--checkpoint", f"mine={plain_sb3 / 'model.zip'}:ppo"]
    args += ["--normalizer", f"mine={plain_sb3 / 'vecnormalize.pkl'}"]
    args += ["--adversaries", "nominal", "--budgets", "--workers", "2"]
    assert main(args) == 0
    got = {int(r["seed"]): float(r["true_return"]) for r in rows(tmp_path / "results")}
    assert {r["adversary"] for r in rows(tmp_path / "results")} == {"nominal"}
    want = plain_returns(plain_sb3, [s * SEED_STRIDE for s in (0, 1)])
    assert [got[0], got[1]] == want
    assert not (tmp_path / "results" / "budget.csv").exists()


def test_without_its_normalizer_the_model_plays_other_episodes(plain_sb3: Path) -> None:
    raw = sb3_protagonist(plain_sb3 / "model.zip", raw_observations=True)
    normed = sb3_protagonist(plain_sb3 / "model.zip", normalizer=plain_sb3 / "vecnormalize.pkl")
    obs = gym.make("Hopper-v5").reset(seed=0)[0]
    info = check_protagonists("Hopper-v5", {"raw": raw, "normed": normed})
    assert set(info) == {"raw", "normed"}
    from advgame.core.episodes import build_policies
    from advgame.core.registry import make

    game = make("Hopper-v5", disruptors={})
    a = build_policies(game, {"protagonist": raw})["protagonist"].act(obs)
    b = build_policies(game, {"protagonist": normed})["protagonist"].act(obs)
    assert not np.allclose(a, b)


def test_a_checkpoint_without_a_normalizer_or_the_raw_flag_is_refused(
    plain_sb3: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["evaluate", "--scenario", "Hopper-v5", "--out", str(tmp_path / "r")]
    args += ["--checkpoint", f"mine={plain_sb3 / 'model.zip'}", "--adversaries", "nominal"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "--normalizer mine=" in err and "--raw-obs mine" in err
    assert "vecnormalize.pkl" in err  # the file beside the model is suggested
    with pytest.raises(ConfigError, match="normalizer"):
        sb3_protagonist(plain_sb3 / "model.zip")


def test_a_normalizer_that_is_missing_or_of_another_shape_is_refused(
    plain_sb3: Path, tmp_path: Path
) -> None:
    with pytest.raises(ConfigError, match="No normalizer file"):
        sb3_protagonist(plain_sb3 / "model.zip", normalizer=tmp_path / "nope.pkl")
    np.savez(tmp_path / "stats.npz", mean=np.zeros(3), var=np.ones(3))
    wrong = sb3_protagonist(plain_sb3 / "model.zip", normalizer=tmp_path / "stats.npz")
    with pytest.raises(ConfigError, match=r"shape \(3,\).*\(11,\)"):
        check_protagonists("Hopper-v5", {"wrong": wrong})


def test_a_checkpoint_of_other_spaces_names_both_spaces(
    plain_sb3: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["evaluate", "--scenario", "HalfCheetah-v5", "--out", str(tmp_path / "r")]
    args += ["--checkpoint", f"mine={plain_sb3 / 'model.zip'}", "--raw-obs", "mine"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "Box(" in err and "(11,)" in err and "(17,)" in err and "HalfCheetah-v5" in err
    assert not (tmp_path / "r").exists()  # refused before anything ran


def test_each_population_snapshot_is_its_own_column(atla_run: Path) -> None:
    columns = adversary_columns("Hopper-v5", [f"population:{atla_run}"])
    assert list(columns) == [
        "nominal",
        "population atla@0",
        "population atla@1",
        "population atla@2",
    ]
    paths = [c.specs["observation_adversary"].path for c in list(columns.values())[1:]]
    assert len(set(paths)) == 3 and all(Path(p).is_file() for p in paths)
    assert all(c.make_kwargs == {"preset": "atla"} for c in list(columns.values())[1:])
    last = adversary_columns("Hopper-v5", [f"population:{atla_run}"], last=2)
    assert list(last)[1:] == ["population atla@1", "population atla@2"]
    one = adversary_columns("Hopper-v5", [f"population:{atla_run},sample=2"], seed=3)
    assert len(one) == 3 and set(one) < set(columns)
    file_cols = adversary_columns("Hopper-v5", [f"population:{atla_run / 'population.json'}"])
    assert list(file_cols) == list(columns)


def test_column_specs_that_do_not_parse_say_how_to_fix_them(atla_run: Path) -> None:
    with pytest.raises(UnknownNameError, match='Did you mean "population"'):
        adversary_columns("Hopper-v5", ["popluation:runs/x"])
    with pytest.raises(UnknownNameError, match=r'Did you mean "state-gauss-0\.1"'):
        adversary_columns("Hopper-v5", ["preset:state-gaus-0.1"])
    with pytest.raises(ConfigError, match="last=K"):
        adversary_columns("Hopper-v5", [f"population:{atla_run},last=0"])
    with pytest.raises(ConfigError, match=r"no population\.json"):
        adversary_columns("Hopper-v5", ["population:/nonexistent/run"])


def test_default_columns_are_todays(atla_run: Path) -> None:
    columns = adversary_columns("Hopper-v5", runs={"atla": atla_run})
    assert next(iter(columns)) == "nominal" and "learned (atla)" in columns
    assert "random state-gauss-0.1" in columns and "scheduled shift-sinusoid" in columns
    latest = columns["learned (atla)"].specs["observation_adversary"]
    assert (
        latest
        == adversary_columns("Hopper-v5", [f"population:{atla_run}"], last=1)[
            "population atla@2"
        ].specs["observation_adversary"]
    )
    assert isinstance(columns["nominal"], AdversarySetup)
    other = adversary_columns("Hopper-v5", ["nominal", f"learned:{atla_run}"])
    assert list(other) == ["nominal", "learned (atla)"]
    assert other["learned (atla)"] == columns["learned (atla)"]


def test_a_population_file_outside_a_run_needs_its_preset(atla_run: Path, tmp_path: Path) -> None:
    Population.load(atla_run / "population.json").save(tmp_path / "attackers.json")
    spec = f"population:{tmp_path / 'attackers.json'}"
    with pytest.raises(ConfigError, match="preset=atla"):
        adversary_columns("Hopper-v5", [spec])
    columns = adversary_columns("Hopper-v5", [f"{spec},preset=atla,last=2"])
    assert list(columns) == ["nominal", "population attackers@1", "population attackers@2"]
    assert all(
        Path(c.specs["observation_adversary"].path).is_file() for c in columns.values() if c.specs
    )


def test_a_population_and_a_preset_from_the_cli_then_a_moved_folder_re_reports(
    plain_sb3: Path, atla_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    args = ["evaluate", str(atla_run), "--out", "results", "--seeds", "1", "--workers", "1"]
    args += ["--checkpoint", f"mine={plain_sb3 / 'model.zip'}:ppo"]
    args += ["--normalizer", f"mine={plain_sb3 / 'vecnormalize.pkl'}", "--budgets"]
    args += ["--adversaries", "preset:state-gauss-0.1", f"population:{atla_run}", "--last", "3"]
    assert main(args) == 0
    table = rows(tmp_path / "results")
    cols = ["nominal", "preset state-gauss-0.1", *(f"population atla@{i}" for i in range(3))]
    assert list(dict.fromkeys(r["adversary"] for r in table)) == cols
    assert {r["protagonist"] for r in table} == {"atla", "mine"}
    report = (tmp_path / "results" / "report.md").read_text()
    listing = report.split("## Adversary columns", 1)[1]
    for i in range(3):
        assert f"checkpoints/iter_000{i}" in listing
    assert "state-gauss-0.1" in listing
    moved = tmp_path / "elsewhere" / "shared-results"
    shutil.move(tmp_path / "results", moved)
    (moved / "training.png").unlink()
    monkeypatch.chdir(tmp_path / "elsewhere")
    hidden = atla_run.with_name("atla-hidden")
    atla_run.rename(hidden)  # the folder stands on its own: the run is not needed
    try:
        assert main(["report", "shared-results"]) == 0
    finally:
        hidden.rename(atla_run)
    assert (moved / "training.png").read_bytes()[:4] == b"\x89PNG"
    runs = json.loads((moved / "runs.json").read_text())
    assert not Path(runs["atla"]["progress"]).is_absolute()


def test_a_team_checkpoint_plays_as_its_run_does(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("gymnasium_robotics", reason="MA-HalfCheetah-2x3 needs the mamujoco extra")
    monkeypatch.chdir(tmp_path)
    args = ["train", "--scenario", "MA-HalfCheetah-2x3", "--preset", "partial"]
    args += ["--iterations", "1", "--protagonist-steps", "128", "--adversary-steps", "128"]
    args += ["--set", 'protagonist_algo="mappo"', "--set", 'protagonist_hparams={"n_steps": 64}']
    args += ["--set", 'adversary_hparams={"n_steps": 64}', "--no-progress", "--run-dir", "ma"]
    assert main(args) == 0
    actors = next(Path("ma").glob("checkpoints/iter_*/mappo_actors.pt"))
    args = ["evaluate", "ma", "--team", f"copy={actors}", "--out", "res", "--seeds", "2"]
    assert main([*args, "--adversaries", "nominal", "learned", "--budgets", "--workers", "1"]) == 0
    table = rows(Path("res"))
    assert {r["adversary"] for r in table} == {"nominal", "learned (ma)"}
    by = {(r["protagonist"], r["adversary"], r["seed"]): float(r["true_return"]) for r in table}
    assert len(by) == 8
    assert all(by[("copy", a, s)] == by[("ma", a, s)] for _, a, s in by)
    assert by[("ma", "nominal", "0")] != by[("ma", "nominal", "1")]


def test_a_callable_of_the_wrong_action_shape_is_refused_before_it_plays(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["evaluate", "--scenario", "Hopper-v5", "--out", str(tmp_path / "r")]
    assert main([*args, "--callable", "zeros=numpy:zeros_like", "--adversaries", "nominal"]) == 2
    err = capsys.readouterr().err
    assert "'zeros'" in err and "shape (11,)" in err and "(3,)" in err
    assert not (tmp_path / "r").exists()


def test_evaluate_help_lists_the_column_kinds(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for kind in ("preset:NAME", "population:RUN_DIR|FILE", "learned[:RUN_DIR]", "--raw-obs"):
        assert kind in text


def test_a_folder_with_an_old_runs_json_still_finds_the_curves(
    atla_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    args = ["evaluate", str(atla_run), "--out", "res", "--seeds", "1", "--workers", "1"]
    assert main([*args, "--adversaries", "nominal", "--budgets"]) == 0
    (tmp_path / "res" / "runs.json").write_text(json.dumps({"atla": str(atla_run)}))
    shutil.rmtree(tmp_path / "res" / "progress")
    (tmp_path / "res" / "training.png").unlink()
    assert main(["report", "res"]) == 0
    assert (tmp_path / "res" / "training.png").is_file()
    assert f"run `{atla_run}`" in (tmp_path / "res" / "report.md").read_text()
