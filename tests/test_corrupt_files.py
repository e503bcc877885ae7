"""Files advgame wrote and reads back: a truncated, empty or garbled one is a `FileFormatError`
naming the file and saying what it looks like, never a traceback from json, csv or SB3."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from advgame.cli import main
from advgame.core.config import load_json
from advgame.errors import FileFormatError
from advgame.evaluation import PayoffTable
from advgame.training import TrainConfig
from advgame.training.population import Population


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory, tiny_atla: Callable[..., list[str]]) -> Path:
    """A tiny finished ATLA run."""
    folder = tmp_path_factory.mktemp("runs") / "atla"
    assert main(["train", *tiny_atla(1), "--run-dir", str(folder)]) == 0
    return folder


@pytest.fixture
def copy(run: Path, tmp_path: Path) -> Path:
    """A copy of the run to damage."""
    return Path(shutil.copytree(run, tmp_path / "atla"))


def cut(path: Path, keep: float = 0.5) -> None:
    """Truncate `path` to a fraction of its bytes, as an interrupted copy would."""
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def test_resume_with_a_truncated_state_says_so(
    copy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cut(copy / "state.json")
    assert main(["resume", str(copy), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "state.json" in err and "truncated" in err and "Traceback" not in err


def test_an_empty_config_and_a_garbled_population_say_so(run: Path, copy: Path) -> None:
    (copy / "config.json").write_text("")
    with pytest.raises(FileFormatError, match=r"config\.json.*empty"):
        load_json(TrainConfig, copy / "config.json")
    (copy / "population.json").write_text('{"not": "a list"}')
    with pytest.raises(FileFormatError, match=r"population\.json.*not a list"):
        Population.load(copy / "population.json")
    shutil.copyfile(run / "config.json", copy / "config.json")
    (copy / "state.json").write_text('{"iteration": 1}')
    with pytest.raises(FileFormatError, match="another version"):
        from advgame.evaluation import run_protagonist

        run_protagonist(copy)


def test_evaluate_with_a_truncated_protagonist_checkpoint_says_so(
    copy: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (zip_path,) = copy.glob("checkpoints/*/protagonist.zip")
    cut(zip_path)
    args = ["evaluate", str(copy), "--out", str(copy / "res"), "--seeds", "1", "--workers", "1"]
    assert main([*args, "--adversaries", "nominal", "--budgets"]) == 2
    err = capsys.readouterr().err
    assert "protagonist.zip" in err and ("truncated" in err or "not a zip" in err)


@pytest.mark.parametrize("content", [b"", b"not a zip at all", b"PK\x03\x04broken"])
def test_a_checkpoint_option_that_is_not_a_model_says_so(
    tmp_path: Path, content: bytes, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "file.zip"
    bad.write_bytes(content)
    args = ["evaluate", "--scenario", "Hopper-v5", "--out", str(tmp_path / "r")]
    assert main([*args, "--checkpoint", f"m={bad}:ppo", "--raw-obs", "m"]) == 2
    err = capsys.readouterr().err
    assert "file.zip" in err and "Traceback" not in err


def test_report_on_a_cut_payoff_table_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rows = [
        {"protagonist": "p", "adversary": a, "seed": s, "true_return": 1.0 + s, "length": 10}
        for a in ("nominal", "gauss")
        for s in range(3)
    ]
    folder = tmp_path / "res"
    table = PayoffTable(rows)
    table.to_csv(folder / "payoff.csv")
    table.to_json(folder / "payoff.json")
    cut(folder / "payoff.csv", 0.8)
    assert main(["report", str(folder)]) == 2
    err = capsys.readouterr().err
    assert "payoff.csv" in err and "truncated" in err
    cut(folder / "payoff.json", 0.5)
    with pytest.raises(FileFormatError, match=r"payoff\.json.*truncated"):
        PayoffTable.from_json(folder / "payoff.json")
