"""PSRO-style population training: the meta-game grows, and a SIGKILLed run resumes.

A tiny run: InvertedPendulum with RARL forces, 50-step episodes, 128-step PPO best
responses, 2 iterations after the seeding one.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from advgame.errors import ConfigError
from advgame.training.population import Population
from advgame.workflows.metasolver import nash
from advgame.workflows.psro import PSROConfig, load_meta, resume_psro, run_psro

TINY = PSROConfig(
    scenario="InvertedPendulum-v5",
    preset="rarl",
    iterations=2,
    protagonist_steps=128,
    adversary_steps=128,
    protagonist_hparams={"n_steps": 64},
    adversary_hparams={"n_steps": 64},
    eval_seeds=2,
    max_episode_steps=50,
)


@pytest.fixture(scope="module")
def whole_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny run, uninterrupted, in this process."""
    return run_psro(TINY, tmp_path_factory.mktemp("psro") / "run")


def test_each_iteration_adds_one_best_response_per_side(whole_run: Path) -> None:
    meta = load_meta(whole_run)
    assert [m["iteration"] for m in meta] == [0, 1, 2]
    for m in meta:
        k = m["iteration"]
        assert m["protagonists"] == [f"protagonist@{i}" for i in range(k + 1)]
        assert m["adversaries"] == ["force_adversary:noop"] + [
            f"force_adversary@{i}" for i in range(1, k + 1)
        ]
        matrix = np.array(m["matrix"])
        assert matrix.shape == (k + 1, k + 1) and np.isfinite(matrix).all()
        row, col = nash(matrix)  # the stored strategies are the solver's, of this matrix
        np.testing.assert_allclose(m["protagonist_strategy"], row, atol=1e-9)
        np.testing.assert_allclose(m["adversary_strategy"], col, atol=1e-9)
    # the matrix only grows: earlier entries are kept as they were
    assert np.array(meta[2]["matrix"])[:2, :2].tolist() == meta[1]["matrix"]
    members = Population.load(whole_run / "population.json")
    assert all(Path(m.spec.path).is_file() for m in members if m.learned)
    report = (whole_run / "report.md").read_text()
    assert "### Iteration 2 (nash" in report and "| protagonist@2 |" in report


_CHILD = """
import sys
from advgame.workflows.psro import PSROConfig, run_psro
cfg = PSROConfig(**{cfg})
run_psro(cfg, sys.argv[1], workers=2)
"""


def _mtimes(folder: Path) -> dict[str, int]:
    return {
        str(p.relative_to(folder)): p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file()
    }


def test_a_sigkilled_run_resumes_without_recomputing(whole_run: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    fields = {k: getattr(TINY, k) for k in TINY.__dataclass_fields__}
    code = _CHILD.format(cfg=repr(fields))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    child = subprocess.Popen(
        [sys.executable, "-c", code, str(run)], env=env, start_new_session=True
    )
    try:
        deadline = time.monotonic() + 240
        while len(list((run / "jobs").glob("*.pkl"))) < 2:  # iteration 1 half trained
            assert child.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.02)
        os.killpg(child.pid, signal.SIGKILL)  # the run and its pool's workers
    finally:
        child.wait()
    assert len(load_meta(run)) < 3
    before = {
        k: v
        for k, v in _mtimes(run).items()
        if k.startswith(("jobs/", "payoff/parts/", "checkpoints/"))
    }
    assert any(k.startswith("payoff/parts/") for k in before) and any(
        k.startswith("jobs/") for k in before
    )
    resume_psro(run)
    after = _mtimes(run)
    redone = sorted(k for k, v in before.items() if after.get(k) != v)
    assert not redone, f"finished files written again on resume: {redone}"
    assert json.loads((run / "meta.json").read_text()) == load_meta(whole_run)  # as if never killed


def test_the_psro_command_runs_and_resumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from advgame.cli import main

    run = tmp_path / "cli"
    args = ["psro", "--run-dir", str(run), "--scenario", "InvertedPendulum-v5", "--iterations", "0"]
    args += [
        "--protagonist-steps",
        "64",
        "--set",
        'protagonist_hparams={"n_steps": 32, "batch_size": 32}',
    ]
    args += ["--eval-seeds", "1", "--max-episode-steps", "20", "--solver", "uniform"]
    assert main(args) == 0
    (entry,) = load_meta(run)
    err = capsys.readouterr().err  # a line per iteration (stderr is a file here)
    assert "psro cli: 1/1 iterations (100 %)" in err
    assert f"iteration 0: game value {entry['value']:,.1f}, 1 protagonists x 1 adversaries" in err
    assert entry["solver"] == "uniform" and entry["protagonists"] == ["protagonist@0"]
    assert json.loads((run / "config.json").read_text())["protagonist_hparams"] == {
        "n_steps": 32,
        "batch_size": 32,
    }
    assert main(["psro", "--run-dir", str(run), "--resume"]) == 0
    assert load_meta(run) == [entry]


def test_a_run_directory_is_not_started_twice_and_configs_are_checked(whole_run: Path) -> None:
    with pytest.raises(ConfigError, match="resume_psro"):
        run_psro(TINY, whole_run)
    assert resume_psro(whole_run) == whole_run  # finished: nothing to do
    with pytest.raises(ConfigError, match="solver"):
        PSROConfig(solver="nahs")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="force_adversary"):
        run_psro(
            PSROConfig(scenario="InvertedPendulum-v5", adversary="wind"), whole_run.parent / "x"
        )


def test_unit_keys_depend_on_values_not_on_shared_objects() -> None:
    """A spec built here and the same spec read back from JSON name the same part file."""
    from advgame.agents.common.checkpoint import SB3Checkpoint
    from advgame.runner.run import unit_key

    path = "/runs/x/protagonist.zip"
    shared = (SB3Checkpoint(path, "ppo", None), SB3Checkpoint(path, "ppo", None))
    copies = json.loads(json.dumps([[path, "ppo"], [path, "ppo"]]))
    read_back = tuple(SB3Checkpoint(p, a, None) for p, a in copies)
    assert shared[0].path is shared[1].path and read_back[0].path is not read_back[1].path
    assert unit_key(shared) == unit_key(read_back)
    assert unit_key(shared) != unit_key((shared[0], SB3Checkpoint(path, "sac", None)))


def test_a_run_killed_between_members_and_population_resumes_without_redoing(
    tmp_path: Path,
) -> None:
    """Killed after writing iteration 1's members, before saving the population or meta-game:
    the resume reads both best responses back from their part files and leaves their
    checkpoint files as they are."""
    import dataclasses

    run = run_psro(dataclasses.replace(TINY, iterations=1), tmp_path / "run")
    members = json.loads((run / "population.json").read_text())
    (run / "population.json").write_text(json.dumps([m for m in members if m["iteration"] < 1]))
    (run / "meta.json").write_text(json.dumps(load_meta(run)[:1]))
    before = _mtimes(run)
    jobs = sorted(p.name for p in (run / "jobs").glob("*.pkl"))
    resume_psro(run)
    after = _mtimes(run)
    assert sorted(p.name for p in (run / "jobs").glob("*.pkl")) == jobs  # no job run again
    redone = sorted(k for k, v in before.items() if k.startswith("checkpoints/") and after[k] != v)
    assert not redone, f"checkpoint files written again: {redone}"
    assert [m["iteration"] for m in load_meta(run)] == [0, 1]


@pytest.mark.parametrize("algo", ["ompo", "dbc", "rsc"])
def test_the_papers_off_policy_baselines_train_as_psro_protagonists(
    algo: str, tmp_path: Path
) -> None:
    """Each best response is the named learner, saved and played back as that learner."""
    small = {"net_arch": [16, 16], "learning_starts": 32, "batch_size": 16}
    if algo == "dbc":
        small |= {"feature_dim": 8, "encoder_arch": [16], "model_width": 16}
    cfg = PSROConfig(scenario="InvertedPendulum-v5", preset="rarl", iterations=1,
                     protagonist_steps=64, adversary_steps=64, protagonist_algo=algo,
                     protagonist_hparams=small, adversary_hparams={"n_steps": 32, "batch_size": 32},
                     eval_seeds=1, max_episode_steps=20)  # fmt: skip
    run = run_psro(cfg, tmp_path / "run")
    protagonists = [m for m in Population.load(run / "population.json") if m.agent == "protagonist"]
    assert [m.spec.algo for m in protagonists] == [algo, algo]
    assert all(Path(m.spec.path).is_file() for m in protagonists)
    assert np.isfinite(np.array(load_meta(run)[-1]["matrix"])).all()  # played back as `algo`
