"""The ``advgame`` command: real runs of every sub-command through `advgame.cli.main`, and the
installed console script once in a subprocess."""

from __future__ import annotations

import csv
import dataclasses
import json
import re
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from advgame.cli import main
from advgame.core.config import load_json, save_json
from advgame.core.registry import list_scenarios, scenario_spec
from advgame.training import METHODS, TrainConfig

PNG = b"\x89PNG\r\n\x1a\n"
WALL_CLOCK = ("fps", "wall_s")


def assert_png(path: Path) -> None:
    data = path.read_bytes()
    assert data[:8] == PNG and len(data) > 1000, path


def progress(run: Path) -> list[dict[str, str]]:
    with (run / "progress.csv").open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory: pytest.TempPathFactory, tiny_atla: Callable[..., list[str]]) -> Path:
    """`advgame train --method atla` with tiny sizes, through `main`."""
    run = tmp_path_factory.mktemp("cli") / "atla"
    assert main(["train", *tiny_atla(), "--run-dir", str(run)]) == 0
    return run


@pytest.fixture(scope="module")
def evaluated(cli_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "eval"
    args = ["evaluate", str(cli_run), "--out", str(out), "--seeds", "1", "--workers", "1"]
    assert main(args) == 0
    return out


# -- list -------------------------------------------------------------------------------------
def test_list_prints_every_scenario(capsys) -> None:
    assert main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list(list_scenarios())
    assert any(line.startswith("Hopper-v5 ") and "mujoco" in line for line in lines)


def test_list_presets_shows_each_preset_with_its_description(capsys) -> None:
    assert main(["list", "--presets", "Hopper-v5"]) == 0
    out = capsys.readouterr().out
    presets = scenario_spec("Hopper-v5").load_presets()
    assert {"atla", "rarl", "default"} <= set(presets)
    for name, preset in presets.items():
        assert f"    {name:24s} {preset.description}" in out
    assert out.splitlines()[0].startswith("Hopper-v5")


def test_robosuites_per_env_info_lines_are_shown_only_with_verbose(capsys) -> None:
    import logging

    logger = logging.getLogger("robosuite_logs")

    def record(level: int) -> logging.LogRecord:
        return logger.makeRecord(
            logger.name, level, __file__, 1, "Loading controller ...", (), None
        )

    assert main(["list"]) == 0
    assert not logger.filter(record(logging.INFO)) and logger.filter(record(logging.WARNING))
    assert not logger.propagate  # robosuite's own handler prints; the root's would repeat it
    logger.filters.clear()  # as a -v run finds it
    assert main(["-v", "list"]) == 0
    assert logger.filter(record(logging.INFO))
    capsys.readouterr()


def _robosuite_logger_state(_: int) -> tuple[bool, bool]:
    """In a worker: (propagates, lets INFO through) for robosuite's logger."""
    import logging

    logger = logging.getLogger("robosuite_logs")
    info = logger.makeRecord(logger.name, logging.INFO, __file__, 1, "Loading ...", (), None)
    return logger.propagate, bool(logger.filter(info))


def test_pool_workers_quiet_robosuite_as_the_command_line_did() -> None:
    """Most envs of an evaluation are built in pool workers: they follow the command line."""
    from advgame.core.library_logs import quiet_libraries
    from advgame.runner import local
    from advgame.runner.run import run_units

    try:
        quiet_libraries(True)
        local.shutdown()  # fresh workers, started with this process's environment
        records = run_units(_robosuite_logger_state, [0, 1], workers=2, start_method="spawn")
        assert [r.value for r in records] == [(False, False)] * 2  # without it: (True, True)
    finally:
        local.shutdown()


def test_an_unknown_scenario_exits_2_with_a_suggestion(capsys, tmp_path: Path) -> None:
    assert main(["list", "Hoper-v5"]) == 2
    err = capsys.readouterr().err
    assert 'Did you mean "Hopper-v5"' in err and "Traceback" not in err
    assert main(["train", "--scenario", "Hoper-v5", "--run-dir", str(tmp_path / "r")]) == 2
    assert 'Did you mean "Hopper-v5"' in capsys.readouterr().err


def test_the_installed_script_reports_errors_with_exit_code_2() -> None:
    script = Path(sys.executable).with_name("advgame")
    script = script if script.exists() else Path(shutil.which("advgame") or "advgame")
    done = subprocess.run(
        [str(script), "list", "Hoper-v5"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 2
    assert done.stderr.startswith("advgame list: error: No scenario 'Hoper-v5'.")
    assert 'Did you mean "Hopper-v5"' in done.stderr and "Traceback" not in done.stderr
    assert done.stdout == ""


# -- train ------------------------------------------------------------------------------------
def test_train_help_mentions_every_config_field(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["train", "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    flags = set(re.findall(r"--[a-z][a-z-]*", text))
    # fields without their own flag must at least be named where --set is explained
    set_help = re.search(r"^  --set KEY=VALUE(.*?)^  --", text, re.S | re.M)
    assert set_help, text
    missing = [
        f.name
        for f in dataclasses.fields(TrainConfig)
        if "--" + f.name.replace("_", "-") not in flags
        and not re.search(rf"\b{f.name}\b", set_help.group(1))
    ]
    assert not missing, f"`advgame train --help` does not mention {missing}"
    for method in METHODS:
        assert method in text


def test_train_writes_a_run_with_the_overrides(cli_run: Path, capsys) -> None:
    cfg = load_json(TrainConfig, cli_run / "config.json")
    assert cfg.preset == "atla" and cfg.iterations == 2 and cfg.eval_episodes == 1
    assert cfg.protagonist_hparams == {"n_steps": 64} == cfg.adversary_hparams
    assert json.loads((cli_run / "state.json").read_text())["iteration"] == 2
    assert [int(r["iteration"]) for r in progress(cli_run)] == [1, 2]
    assert (cli_run / "checkpoints" / "iter_0002" / "protagonist.zip").is_file()


def test_train_rejects_an_unknown_option_before_creating_the_run(capsys, tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert main(["train", "--set", "iteration=3", "--run-dir", str(run)]) == 2
    assert 'Did you mean "iterations"' in capsys.readouterr().err
    assert not run.exists()
    assert main(["train", "--set", "iterations", "--run-dir", str(run)]) == 2
    assert "key=value" in capsys.readouterr().err


@pytest.mark.parametrize("base", ["ppo", "rarl"])
def test_a_method_on_top_of_a_config_file_gives_that_method(base: str, tmp_path: Path) -> None:
    # `--config other_run/config.json --method atla` must train ATLA: not inherit `learned=[]`
    # from a PPO run, nor RARL's half training budget.
    save_json(TrainConfig(**METHODS[base]), tmp_path / "base.json")
    run = tmp_path / "run"
    args = ["train", "--config", str(tmp_path / "base.json"), "--method", "atla"]
    args += ["--iterations", "1", "--protagonist-steps", "32", "--adversary-steps", "32"]
    args += ["--eval-episodes", "0", "--no-progress", "--run-dir", str(run)]
    args += [
        "--set",
        'protagonist_hparams={"n_steps": 32, "batch_size": 32}',
        "--set",
        'adversary_hparams={"n_steps": 32, "batch_size": 32}',
    ]
    assert main(args) == 0
    cfg = load_json(TrainConfig, run / "config.json")
    assert cfg.preset == "atla"
    assert cfg.learned is None, f"atla on a {base} config learns {cfg.learned}"
    assert cfg.train_budget_scale == 1.0, f"atla on a {base} config trains at a scaled budget"


# -- resume -----------------------------------------------------------------------------------
def test_resume_of_a_run_killed_before_its_first_iteration_trains_it_whole(
    cli_run: Path, tmp_path: Path, capsys
) -> None:
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(cli_run / "config.json", run / "config.json")  # all a early kill leaves
    assert main(["resume", str(run), "--no-progress"]) == 0
    assert f"run completed in {run}" in capsys.readouterr().out
    rows, reference = progress(run), progress(cli_run)
    assert [r["iteration"] for r in rows] == ["1", "2"]
    for a, b in zip(rows, reference, strict=True):  # same config and seed: the same numbers
        assert {k: v for k, v in a.items() if k not in WALL_CLOCK} == {
            k: v for k, v in b.items() if k not in WALL_CLOCK
        }


def test_resume_without_a_run_exits_2(tmp_path: Path, capsys) -> None:
    assert main(["resume", str(tmp_path / "nothing")]) == 2
    assert "no config.json" in capsys.readouterr().err


# -- evaluate and report ----------------------------------------------------------------------
def test_evaluate_writes_the_report_and_its_data(evaluated: Path, cli_run: Path) -> None:
    for name in ("report.md", "payoff.csv", "payoff.json", "budget.csv"):
        assert (evaluated / name).is_file(), name
    for name in ("heatmap.png", "budget.png"):
        assert_png(evaluated / name)
    with (evaluated / "payoff.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert {r["protagonist"] for r in rows} == {cli_run.name}
    adversaries = {r["adversary"] for r in rows}
    assert {"nominal", f"learned ({cli_run.name})"} <= adversaries
    assert {r["seed"] for r in rows} == {"0"}
    data = json.loads((evaluated / "payoff.json").read_text())
    assert len(data["rows"]) == len(rows)
    report = (evaluated / "report.md").read_text()
    assert "heatmap.png" in report and "budget.png" in report and cli_run.name in report


def test_evaluate_logs_progress_unless_told_not_to(cli_run: Path, tmp_path: Path, capsys) -> None:
    args = ["evaluate", str(cli_run), "--seeds", "1", "--workers", "1", "--budgets"]
    args += ["--adversaries", "nominal"]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    assert "evaluate: " in capsys.readouterr().err  # stderr is not a terminal here: lines
    assert main([*args, "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    assert "evaluate: " not in capsys.readouterr().err
    assert main([*args, "--out", str(tmp_path / "c"), "--exploitability", "-5"]) == 2
    assert ">= 0 (0: no search); got -5" in capsys.readouterr().err


def test_report_rebuilds_the_report_from_the_data(evaluated: Path, capsys) -> None:
    payoff = (evaluated / "payoff.csv").read_text()
    report = (evaluated / "report.md").read_text()
    for name in ("report.md", "heatmap.png", "budget.png"):
        (evaluated / name).unlink()
    assert main(["report", str(evaluated)]) == 0
    assert f"report: {evaluated / 'report.md'}" in capsys.readouterr().out
    assert (evaluated / "report.md").read_text() == report
    assert_png(evaluated / "heatmap.png")
    assert_png(evaluated / "budget.png")
    assert (evaluated / "payoff.csv").read_text() == payoff


def test_report_of_a_folder_without_an_evaluation_exits_2(tmp_path: Path, capsys) -> None:
    assert main(["report", str(tmp_path)]) == 2
    assert "payoff.csv" in capsys.readouterr().err


# -- demo -------------------------------------------------------------------------------------
def test_quick_demo_trains_evaluates_and_prints_the_report_path(tmp_path: Path, capsys) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--out", str(out), "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert f"report: {out / 'report.md'}" in printed
    from advgame.workflows import zoo

    released = [e.id for e in zoo.entries() if e.scenario == "Hopper-v5" and "adversary" in e.files]
    if released:  # the repository's zoo: each released agent's row, under its own adversary
        assert f"zoo report: {out / 'zoo' / 'report.md'}" in printed
        zoo_report = (out / "zoo" / "report.md").read_text()
        assert all(f"| {r} |" in zoo_report for r in released) and "attack optimal" in zoo_report
    safe = [e.id for e in zoo.entries() if e.scenario == "SafetyHopper-v5"]
    if safe:  # the released safe agents, nominally and under action noise, with their cost
        assert f"safe report: {out / 'safe' / 'report.md'}" in printed
        from advgame.evaluation.table.payoff import PayoffTable

        table = PayoffTable.from_csv(out / "safe" / "payoff.csv")
        assert sorted(table.protagonists) == sorted(safe)
        assert set(table.adversaries) == {"nominal", "preset action-gauss-0.3"}
        cost = {
            c["protagonist"]: c["cost"] for c in table.safety(25) if c["adversary"] == "nominal"
        }
        if {"safetyhopper/ppo", "safetyhopper/pcrpo"} <= set(cost):  # the constraint binds
            assert cost["safetyhopper/ppo"] > 25 >= cost["safetyhopper/pcrpo"]
        assert all(f"  {p} " in printed for p in safe)
    report = (out / "report.md").read_text()
    assert "ppo" in report and "atla" in report
    assert "attack mad" in report and "attack critic" in report  # the worst-of-attacks suite
    for method in ("ppo", "atla"):
        assert json.loads((out / "runs" / method / "state.json").read_text())["iteration"] == 2
    assert_png(out / "heatmap.png")
