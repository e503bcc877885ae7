"""Every file advgame reads back, damaged: a `FileFormatError` that names it, never a traceback.

A tiny real ATLA run and its evaluation write the files (state.json, config.json,
population.json, progress.csv, the protagonist checkpoint and its normalizer, payoff.csv and
payoff.json); SB3 writes a VecNormalize pickle; the executor writes a part file. Each is copied,
then emptied, truncated or has its head garbled, and read back through the loader advgame uses.
The four command-line cases of issue 24 end the file.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from advgame.agents.common.checkpoint import load_model, load_normalizer
from advgame.cli import main
from advgame.core.config import load_json
from advgame.errors import FileFormatError
from advgame.evaluation.table.payoff import PayoffTable
from advgame.runner.run import run_units
from advgame.training import TrainConfig
from advgame.training.loop import append_progress, read_state
from advgame.training.population import Population
from advgame.workflows.psro import load_meta


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory, tiny_atla: Callable[..., list[str]]) -> Path:
    """A finished one-iteration ATLA run on Hopper-v5."""
    out = tmp_path_factory.mktemp("corrupt") / "atla"
    assert main(["train", *tiny_atla(1), "--run-dir", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def results(run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Its evaluation: nominal column only, one seed, no budget sweep."""
    out = tmp_path_factory.mktemp("corrupt") / "eval"
    args = ["evaluate", str(run), "--out", str(out), "--seeds", "1", "--workers", "1"]
    assert main([*args, "--adversaries", "nominal", "--budgets"]) == 0
    (out / "payoff.json").unlink(missing_ok=True)
    PayoffTable.from_csv(out / "payoff.csv").to_json(out / "payoff.json")
    return out


@pytest.fixture(scope="module")
def vecnormalize(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A VecNormalize pickle as plain SB3 saves it."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    path = tmp_path_factory.mktemp("corrupt") / "vecnormalize.pkl"
    venv = VecNormalize(DummyVecEnv([lambda: gym.make("InvertedPendulum-v5")]))
    venv.save(str(path))
    venv.close()
    return path


def _meta(folder: Path) -> Path:
    """A PSRO meta.json as `advgame.workflows.psro` writes it (one solved iteration)."""
    entry = {"iteration": 0, "solver": "nash", "value": 1.5, "protagonists": ["p@0"],
             "adversaries": ["a@0"], "matrix": [[1.5]], "protagonist_strategy": [1.0],
             "adversary_strategy": [1.0]}  # fmt: skip
    path = folder / "meta.json"
    path.write_text(json.dumps([entry], indent=2) + "\n")
    assert load_meta(folder)[0]["value"] == 1.5
    return path


def _part(folder: Path) -> Path:
    """An executor part file of one finished unit."""
    run_units(abs, [-3], parts_dir=folder)
    (path,) = folder.glob("*.pkl")
    return path


def _model(path: Path) -> Any:
    """`load_model` past its per-process cache (keyed by path: each copy is read afresh)."""
    load_model.cache_clear()
    return load_model(str(path), "ppo")


# kind: (where the intact file is, how advgame reads it back from its copy)
KINDS: dict[str, tuple[str, Callable[[Path], Any]]] = {
    "state.json": ("run:state.json", lambda p: read_state(p.parent)),
    "config.json": ("run:config.json", lambda p: load_json(TrainConfig, p)),
    "population.json": ("run:population.json", Population.load),
    "progress.csv": ("run:progress.csv", lambda p: append_progress(p, {"iteration": 9})),
    "checkpoint.zip": ("run:checkpoints/iter_0001/protagonist.zip", lambda p: _model(p)),
    "obs_norm.npz": ("run:checkpoints/iter_0001/protagonist_obs_norm.npz", lambda p: load_normalizer(str(p))),
    "vecnormalize.pkl": ("vecnormalize", lambda p: load_normalizer(str(p))),
    "payoff.csv": ("results:payoff.csv", PayoffTable.from_csv),
    "payoff.json": ("results:payoff.json", PayoffTable.from_json),
    "meta.json": ("meta", lambda p: load_meta(p.parent)),
    "part.pkl": ("part", lambda p: run_units(abs, [-3], parts_dir=p.parent)),
}  # fmt: skip


def damage(path: Path, how: str) -> None:
    """Empty the file, cut it in half (not at a line end), or garble its first bytes."""
    data = path.read_bytes()
    if how == "empty":
        path.write_bytes(b"")
    elif how == "truncated":
        cut = len(data) // 2
        while data[cut - 1 : cut] == b"\n":
            cut -= 1
        path.write_bytes(data[:cut])
    else:
        path.write_bytes(b"\x00\xffgarbage\x80{[" + data[16:])


@pytest.fixture
def intact(request: pytest.FixtureRequest, tmp_path: Path) -> Callable[[str], Path]:
    """A fresh copy of the intact file of `kind`, alone in its own folder."""

    def copy(kind: str) -> Path:
        where = KINDS[kind][0]
        folder = tmp_path / kind.replace(".", "_")
        folder.mkdir()
        if where == "meta":
            return _meta(folder)
        if where == "part":
            return _part(folder)
        if where == "vecnormalize":
            source = request.getfixturevalue("vecnormalize")
        else:
            name, _, rel = where.partition(":")
            source = request.getfixturevalue(name) / rel
        dest = folder / (source.name if kind != "state.json" else "state.json")
        shutil.copy(source, dest)
        KINDS[kind][1](dest)  # the intact copy loads
        return dest

    return copy


@pytest.mark.parametrize("how", ["empty", "truncated", "garbled"])
@pytest.mark.parametrize("kind", sorted(KINDS))
def test_a_damaged_file_is_a_file_format_error_naming_it(
    kind: str, how: str, intact: Callable[[str], Path]
) -> None:
    path = intact(kind)
    damage(path, how)
    with pytest.raises(FileFormatError) as info:
        KINDS[kind][1](path)
    message = str(info.value)
    assert str(path) in message and info.value.path == str(path)
    expected = {"empty": "empty", "truncated": "truncated"}.get(how)
    if expected and kind != "vecnormalize.pkl":  # a cut pickle may fail on a half-read opcode
        assert expected in message, message
    assert "delete" in message.lower() or "rerun" in message.lower() or "again" in message


@pytest.mark.parametrize(
    ("kind", "edit", "fragment"),
    [
        ("state.json", lambda d: {"iteration": d["iteration"]}, "lacks ['rng', 'checkpoint']"),
        ("state.json", lambda d: {**d, "iteration": "3"}, "wrong type"),
        ("population.json", lambda d: {"members": d}, "holds a JSON dict, not a list"),
        ("population.json", lambda d: [{"id": m["id"]} for m in d], "another version"),
        ("payoff.json", lambda d: d["rows"], "not a dict"),
        ("meta.json", lambda d: [{"iteration": 0}], "lacks ['solver', 'value']"),
    ],
    ids=[
        "state-fields",
        "state-types",
        "population-dict",
        "population-members",
        "payoff-list",
        "meta-fields",
    ],
)
def test_a_file_of_another_layout_says_so(
    kind: str, edit: Callable[[Any], Any], fragment: str, intact: Callable[[str], Path]
) -> None:
    path = intact(kind)
    path.write_text(json.dumps(edit(json.loads(path.read_text()))) + "\n")
    with pytest.raises(FileFormatError, match=None) as info:
        KINDS[kind][1](path)
    assert fragment in str(info.value) and str(path) in str(info.value)


# -- the command-line cases of issue 24 ---------------------------------------------------------
def _one_line_error(capsys: pytest.CaptureFixture[str], *fragments: str) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    for fragment in fragments:
        assert fragment in err, f"{fragment!r} not in {err!r}"
    return err


def test_resume_of_a_run_with_a_corrupt_state_json_exits_2(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    (copy / "state.json").write_text('{"iteration": 1, "rng": {"bit_gen')
    assert main(["resume", str(copy), "--no-progress"]) == 2
    _one_line_error(capsys, "state.json", "truncated", "train it again")


def test_evaluate_of_a_run_with_a_truncated_checkpoint_exits_2(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    damage(copy / "checkpoints" / "iter_0001" / "protagonist.zip", "truncated")
    args = ["evaluate", str(copy), "--out", str(tmp_path / "r"), "--seeds", "1"]
    assert main([*args, "--workers", "1", "--adversaries", "nominal", "--budgets"]) == 2
    _one_line_error(capsys, "protagonist.zip", "truncated")


def test_a_checkpoint_option_naming_a_file_that_is_not_a_zip_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fake = tmp_path / "file.zip"
    fake.write_text("not a model\n")
    args = ["evaluate", "--scenario", "Hopper-v5", "--out", str(tmp_path / "r"), "--raw-obs", "m"]
    assert main([*args, "--checkpoint", f"m={fake}:ppo", "--adversaries", "nominal"]) == 2
    _one_line_error(capsys, "file.zip", "not a zip archive")


def test_report_of_a_folder_whose_payoff_csv_was_cut_short_exits_2(
    results: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "results"
    shutil.copytree(results, copy)
    damage(copy / "payoff.csv", "truncated")
    assert main(["report", str(copy)]) == 2
    _one_line_error(capsys, "payoff.csv", "truncated", "advgame evaluate")
