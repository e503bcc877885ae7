"""The alternation loop end to end, on one tiny ATLA run (real SB3 PPO learners on Hopper-v5).

The run directory layout, progress.csv and TensorBoard logs, the population's members, each
iteration training both sides, refusing to train into an existing run, moved runs, resuming a
finished run, seeded reproducibility and the learning-rate decay. The run is a module fixture:
every test here reads the same one.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

import advgame.core.registry
from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.cli import main
from advgame.core.config import load_json
from advgame.core.episodes import rollout
from advgame.errors import ConfigError
from advgame.training import TrainConfig, train
from advgame.training.population import Population
from tests._training_helpers import (
    AGENT,
    HOPPER,
    config,
    final_learning_rate,
    final_protagonist,
    parameters,
    progress_rows,
    same_parameters,
    state,
)

PROGRESS_COLUMNS = (
    "iteration",
    "protagonist_steps",
    "adversary_steps",
    "protagonist_phase_true_return",
    "protagonist_phase_episodes",
    "adversary_phase_true_return",
    "adversary_phase_episodes",
    "adversary_clipped",
    "fps",
    "wall_s",
    "eval_nominal_return",
    "eval_attacked_return",
)
"""The columns the loop documents (README: returns of each side, nominal and attacked
evaluation, clip counts, fps)."""
WALL_CLOCK = ("fps", "wall_s")


@pytest.fixture(scope="module")
def atla_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One tiny ATLA run on Hopper (PPO protagonist, PPO observation adversary)."""
    return train(config("atla"), tmp_path_factory.mktemp("atla") / "run", progress=False)


# -- the run directory ------------------------------------------------------------------------
def test_run_directory_layout(atla_run: Path) -> None:
    cfg = load_json(TrainConfig, atla_run / "config.json")
    assert cfg == config("atla")
    assert state(atla_run)["iteration"] == cfg.iterations
    assert state(atla_run)["checkpoint"] == "checkpoints/iter_0002"
    folders = sorted(p.name for p in (atla_run / "checkpoints").iterdir())
    assert folders == ["iter_0000", "iter_0001", "iter_0002"]  # 0: the untrained adversary
    for name in ("iter_0001", "iter_0002"):
        files = {p.name for p in (atla_run / "checkpoints" / name).iterdir()}
        for agent in ("protagonist", "observation_adversary"):
            assert {f"{agent}.zip", f"{agent}_obs_norm.npz", f"{agent}_vecnormalize.pkl"} <= files
    assert not list(atla_run.rglob("*.partial")) and not list(atla_run.rglob("*.tmp"))


def test_progress_csv_has_one_row_per_iteration_and_the_documented_columns(
    atla_run: Path,
) -> None:
    rows = progress_rows(atla_run)
    assert [int(r["iteration"]) for r in rows] == [1, 2]
    assert set(PROGRESS_COLUMNS) <= set(rows[0])
    for it, row in enumerate(rows, start=1):
        assert int(row["protagonist_steps"]) == 128 * it
        assert int(row["adversary_steps"]) == 128 * it
        assert int(row["protagonist_phase_episodes"]) > 0  # untrained Hopper falls quickly
        assert int(row["adversary_phase_episodes"]) > 0
        for col in ("fps", "wall_s", "eval_nominal_return", "eval_attacked_return"):
            assert math.isfinite(float(row[col])), (col, row[col])
        assert float(row["fps"]) > 0 and float(row["wall_s"]) > 0


def test_tensorboard_gets_the_loop_scalars_and_each_learners_logs(atla_run: Path) -> None:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    loop = EventAccumulator(str(atla_run / "tb" / "loop"))
    loop.Reload()
    assert "loop/eval_attacked_return" in loop.Tags()["scalars"]
    assert [e.step for e in loop.Scalars("loop/eval_nominal_return")] == [1, 2]
    learners = {p.name.rsplit("_", 1)[0] for p in (atla_run / "tb").iterdir() if p.name != "loop"}
    assert learners == {"protagonist", "observation_adversary"}
    for folder in (atla_run / "tb").iterdir():
        assert list(folder.glob("events.out.tfevents.*")), folder


def test_population_members_load_and_play(atla_run: Path) -> None:
    pop = Population.load(atla_run / "population.json")
    agent = "observation_adversary"
    assert [(m.id, m.iteration, m.learned) for m in pop] == [
        (f"{agent}:noop", 0, False),
        (f"{agent}@0", 0, True),
        (f"{agent}@1", 1, True),
        (f"{agent}@2", 2, True),
    ]
    assert all(m.side == "adversary" and m.agent == agent for m in pop)
    for m in pop.of(agent, learned_only=True):
        assert isinstance(m.spec, SB3Checkpoint)
        assert Path(m.spec.path).is_file() and ".partial" not in m.spec.path
        assert Path(m.spec.path).parent.name == f"iter_{m.iteration:04d}"
    game = advgame.core.registry.make(HOPPER, preset="atla", phase="eval")
    protagonist = final_protagonist(atla_run)
    returns = {}
    for m in pop:
        (result,) = rollout(game, {"protagonist": protagonist, agent: m.spec}, seed=3)
        assert result.length > 0 and math.isfinite(result.true_return)
        returns[m.id] = result.true_return
    game.close()
    # the no-op member leaves the task nominal; a trained attacker perturbs it
    (nominal,) = rollout(
        advgame.core.registry.make(HOPPER, preset="atla", phase="eval"),
        {"protagonist": protagonist},
        seed=3,
    )
    assert returns[f"{agent}:noop"] == nominal.true_return
    assert returns[f"{agent}@2"] != nominal.true_return


def test_each_iteration_changes_the_protagonist_and_the_adversary(atla_run: Path) -> None:
    ckpt = atla_run / "checkpoints"
    for agent in ("protagonist", "observation_adversary"):
        first = parameters(ckpt / "iter_0001" / f"{agent}.zip", "ppo")
        second = parameters(ckpt / "iter_0002" / f"{agent}.zip", "ppo")
        assert not same_parameters(first, second), agent
    untrained = parameters(ckpt / "iter_0000" / "observation_adversary.zip", "ppo")
    trained = parameters(ckpt / "iter_0001" / "observation_adversary.zip", "ppo")
    assert not same_parameters(untrained, trained)


def test_train_into_an_existing_run_is_a_clear_error(atla_run: Path, capsys) -> None:
    before = (atla_run / "config.json").read_text()
    with pytest.raises(ConfigError, match="resume") as err:
        train(config("atla", iterations=5), atla_run, progress=False)
    assert str(atla_run) in str(err.value)
    code = main(["train", "--method", "atla", "--run-dir", str(atla_run), "--no-progress"])
    assert code == 2
    assert "advgame resume" in capsys.readouterr().err
    assert (atla_run / "config.json").read_text() == before  # nothing was overwritten


def test_a_moved_run_directory_still_points_at_its_own_checkpoints(
    atla_run: Path, tmp_path: Path
) -> None:
    # Runs are copied off clusters and renamed; state.json stores its checkpoint relative to
    # the run, and the population must too, or a copy silently plays the original's files.
    moved = tmp_path / "moved"
    shutil.copytree(atla_run, moved)
    for m in Population.load(moved / "population.json").of(AGENT, learned_only=True):
        assert Path(m.spec.path).resolve().is_relative_to(moved.resolve()), m.spec.path


def test_resuming_a_finished_run_is_a_no_op(atla_run: Path) -> None:
    before = {
        name: (atla_run / name).read_bytes()
        for name in ("state.json", "progress.csv", "population.json")
    }
    zips = {p: p.read_bytes() for p in (atla_run / "checkpoints").rglob("*.zip")}
    assert main(["resume", str(atla_run), "--no-progress"]) == 0
    for name, data in before.items():
        assert (atla_run / name).read_bytes() == data, name
    assert {p: p.read_bytes() for p in (atla_run / "checkpoints").rglob("*.zip")} == zips


# -- reproducibility --------------------------------------------------------------------------
def test_a_seeded_run_is_reproducible(atla_run: Path, tmp_path: Path) -> None:
    again = train(config("atla"), tmp_path / "again", progress=False)
    rows_a, rows_b = progress_rows(atla_run), progress_rows(again)
    assert len(rows_a) == len(rows_b) == 2
    for a, b in zip(rows_a, rows_b, strict=True):
        assert a.keys() == b.keys()
        for key in a:
            if key not in WALL_CLOCK:
                assert a[key] == b[key], (key, a[key], b[key])
    for agent in ("protagonist", "observation_adversary"):
        path = Path("checkpoints") / "iter_0002" / f"{agent}.zip"
        assert same_parameters(parameters(atla_run / path, "ppo"), parameters(again / path, "ppo"))
    np.testing.assert_array_equal(
        np.load(atla_run / "checkpoints/iter_0002/protagonist_obs_norm.npz")["var"],
        np.load(again / "checkpoints/iter_0002/protagonist_obs_norm.npz")["var"],
    )


def test_another_seed_trains_another_protagonist(atla_run: Path, tmp_path: Path) -> None:
    other = train(config("atla", iterations=1, seed=1), tmp_path / "seed1", progress=False)
    path = Path("checkpoints") / "iter_0001" / "protagonist.zip"
    assert not same_parameters(parameters(atla_run / path, "ppo"), parameters(other / path, "ppo"))


def test_the_learning_rate_decays_to_zero_over_the_run(atla_run: Path) -> None:
    assert final_learning_rate(atla_run, "ppo") == pytest.approx(0.0, abs=1e-12)
