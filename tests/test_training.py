"""The alternation loop end to end: real SB3 learners on real MuJoCo tasks, tiny sizes.

Covers every learner on both sides, the three methods, the run directory layout, seeded
reproducibility, kill-and-resume through the installed ``advgame`` script, population sampling
and config validation.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import advgame.core.registry
import advgame.training.loop
from advgame.adversaries import ConstantAdversary, ZeroAdversary
from advgame.agents.checkpoint import SB3Checkpoint, _algo_class
from advgame.cli import main
from advgame.core.config import load_json
from advgame.core.episodes import rollout
from advgame.errors import ConfigError
from advgame.training import METHODS, TrainConfig, learner_config, train
from advgame.training.population import Member, Population

HOPPER = "Hopper-v5"
PENDULUM = "InvertedPendulum-v5"
OFF_POLICY = {"learning_starts": 32, "buffer_size": 2_000, "batch_size": 32}
TINY: dict[str, Any] = {
    "iterations": 2,
    "protagonist_steps": 128,
    "adversary_steps": 128,
    "protagonist_hparams": {"n_steps": 64},
    "adversary_hparams": {"n_steps": 64},
    "eval_episodes": 1,
}
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
AGENT = "observation_adversary"


def config(method: str, **changes: Any) -> TrainConfig:
    return TrainConfig(**{"scenario": HOPPER, **TINY, **METHODS[method], **changes})


def progress_rows(run: Path) -> list[dict[str, str]]:
    with (run / "progress.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def state(run: Path) -> dict[str, Any]:
    return json.loads((run / "state.json").read_text())


def parameters(zip_path: Path, algo: str) -> dict[str, torch.Tensor]:
    model = _algo_class(algo).load(str(zip_path), device="cpu")
    return {k: v.detach().clone() for k, v in model.policy.state_dict().items()}


def same_parameters(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def final_protagonist(run: Path) -> SB3Checkpoint:
    cfg = load_json(TrainConfig, run / "config.json")
    folder = run / state(run)["checkpoint"]
    return SB3Checkpoint(
        str(folder / "protagonist.zip"),
        cfg.protagonist_algo,
        str(folder / "protagonist_obs_norm.npz"),
        deterministic=True,
    )


def advgame_script() -> str:
    script = Path(sys.executable).with_name("advgame")
    found = script if script.exists() else shutil.which("advgame")
    assert found, "the `advgame` console script is not installed next to this interpreter"
    return str(found)


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


# -- every learner, every method --------------------------------------------------------------
@pytest.fixture(scope="module")
def td3_warmup_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Method "ppo" (no learned adversary) with a TD3 protagonist and a warm-up."""
    cfg = config(
        "ppo",
        scenario=PENDULUM,
        protagonist_algo="td3",
        protagonist_hparams={**OFF_POLICY, "net_arch": [32, 32], "lr_decay": True},
        warmup_steps=64,
    )
    return train(cfg, tmp_path_factory.mktemp("td3") / "run", progress=False)


def test_ppo_method_with_a_td3_protagonist_and_warmup(td3_warmup_run: Path) -> None:
    run = td3_warmup_run
    assert Population.load(run / "population.json").members == []  # nothing learned
    assert sorted(p.name for p in (run / "checkpoints").iterdir()) == ["iter_0001", "iter_0002"]
    rows = progress_rows(run)
    assert [int(r["protagonist_steps"]) for r in rows] == [64 + 128, 64 + 256]
    assert [int(r["adversary_steps"]) for r in rows] == [0, 0]
    assert all(int(r["adversary_phase_episodes"]) == 0 for r in rows)
    # no learned or fixed adversary: the "attacked" evaluation is the nominal one
    assert all(r["eval_attacked_return"] == r["eval_nominal_return"] for r in rows)
    ckpt = run / "checkpoints"
    assert (ckpt / "iter_0002" / "protagonist_replay.pkl").is_file()
    model = _algo_class("td3").load(str(ckpt / "iter_0002" / "protagonist.zip"), device="cpu")
    assert model.learning_starts == 32 and model.buffer_size == 2_000
    first = parameters(ckpt / "iter_0001" / "protagonist.zip", "td3")
    second = parameters(ckpt / "iter_0002" / "protagonist.zip", "td3")
    assert not same_parameters(first, second)


def _final_learning_rate(run: Path, algo: str) -> float:
    folder = run / state(run)["checkpoint"]
    model = _algo_class(algo).load(str(folder / "protagonist.zip"), device="cpu")
    return float(model.lr_schedule(0.0))  # at the end of the last learn() call


def test_the_learning_rate_decays_to_zero_over_the_run(atla_run: Path) -> None:
    assert _final_learning_rate(atla_run, "ppo") == pytest.approx(0.0, abs=1e-12)


def test_the_learning_rate_decays_to_zero_over_a_run_with_warmup(td3_warmup_run: Path) -> None:
    # 64 warm-up + 2 x 128 steps were trained; the decay must span exactly those 320 steps
    assert _final_learning_rate(td3_warmup_run, "td3") == pytest.approx(0.0, abs=1e-12)


def _spy_on_make(monkeypatch: pytest.MonkeyPatch) -> list[tuple[dict[str, Any], Any]]:
    """Record every game the loop builds (training views and quick evaluation); the real
    `make` still builds them."""
    made: list[tuple[dict[str, Any], Any]] = []
    real = advgame.core.registry.make

    def recording(scenario_id: str, **kwargs: Any) -> Any:
        game = real(scenario_id, **kwargs)
        made.append((kwargs, game))
        return game

    monkeypatch.setattr(advgame.core.registry, "make", recording)
    monkeypatch.setattr(advgame.training.loop, "make", recording)
    return made


def test_rarl_trains_at_half_the_force_bound_and_evaluates_at_the_full_bound(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    made = _spy_on_make(monkeypatch)
    cfg = config(
        "rarl",
        scenario=PENDULUM,
        protagonist_algo="sac",
        adversary_algo="sac",
        protagonist_hparams=OFF_POLICY,
        adversary_hparams=OFF_POLICY,
        iterations=3,
        snapshot_every=2,
        sampling="fictitious",
    )
    assert cfg.train_budget_scale == 0.5
    run = train(cfg, tmp_path / "run", progress=False)
    full = 1.0  # advgame.scenarios.mujoco.FORCES["InvertedPendulum-v5"]
    train_games = [g for kw, g in made if kw.get("phase") == "train"]
    eval_games = [g for kw, g in made if kw.get("phase") == "eval"]
    assert len(train_games) == 2  # one view for the protagonist, one for the force adversary
    assert len(eval_games) == cfg.iterations
    for games, bound in ((train_games, 0.5 * full), (eval_games, full)):
        for game in games:
            force = game.disruptors["force_adversary"]
            assert force.spec.max_force == pytest.approx(bound)
            np.testing.assert_allclose(np.abs(force.perturbation(np.ones(force.unit.shape))), bound)

    pop = Population.load(run / "population.json")
    # snapshots every 2 iterations, and always the last one
    assert [m.id for m in pop] == [
        "force_adversary:noop",
        "force_adversary@0",
        "force_adversary@2",
        "force_adversary@3",
    ]
    rows = progress_rows(run)
    assert [int(r["protagonist_steps"]) for r in rows] == [128, 256, 384]
    assert [int(r["adversary_steps"]) for r in rows] == [128, 256, 384]
    ckpt = run / "checkpoints"
    for agent in ("protagonist", "force_adversary"):
        assert (ckpt / "iter_0003" / f"{agent}_replay.pkl").is_file()
        model = _algo_class("sac").load(str(ckpt / "iter_0003" / f"{agent}.zip"), device="cpu")
        assert model.learning_starts == 32
        first = parameters(ckpt / "iter_0001" / f"{agent}.zip", "sac")
        last = parameters(ckpt / "iter_0003" / f"{agent}.zip", "sac")
        assert not same_parameters(first, last), agent


def test_atla_with_a_td3_protagonist_and_a_sac_adversary(tmp_path: Path) -> None:
    cfg = config(
        "atla",
        iterations=1,
        protagonist_algo="td3",
        adversary_algo="sac",
        protagonist_hparams={**OFF_POLICY, "net_arch": [32, 32]},
        adversary_hparams=OFF_POLICY,
    )
    run = train(cfg, tmp_path / "run", progress=False)
    folder = run / "checkpoints" / "iter_0001"
    assert _algo_class("td3").load(str(folder / "protagonist.zip"), device="cpu").policy_delay == 2
    assert (folder / "observation_adversary_replay.pkl").is_file()
    (adversary,) = Population.load(run / "population.json").of(
        "observation_adversary", learned_only=True
    )[-1:]
    assert adversary.spec.algo == "sac" and adversary.iteration == 1
    game = advgame.core.registry.make(HOPPER, preset="atla", phase="eval")
    (result,) = rollout(
        game, {"protagonist": final_protagonist(run), "observation_adversary": adversary.spec}, 0
    )
    game.close()
    assert result.length > 0 and math.isfinite(result.true_return)


# -- kill and resume --------------------------------------------------------------------------
def _wait_for_iteration(proc: subprocess.Popen, run: Path, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()[1]
        try:
            if state(run)["iteration"] >= 1:
                return
        except (FileNotFoundError, json.JSONDecodeError):
            pass
        time.sleep(0.05)
    raise AssertionError(f"no iteration finished in {timeout} s")


def test_a_run_killed_by_sigkill_resumes_to_the_end(
    tmp_path: Path, tiny_atla: Callable[..., list[str]]
) -> None:
    run, iterations = tmp_path / "run", 6
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        [advgame_script(), "train", *tiny_atla(iterations), "--run-dir", str(run)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        _wait_for_iteration(proc, run)
        time.sleep(0.3)  # most likely inside the next iteration now
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.communicate()
    assert proc.returncode == -signal.SIGKILL

    # what a kill leaves is consistent: the last committed iteration, whole
    done = state(run)["iteration"]
    assert 1 <= done < iterations, "the kill came too late to test resume"
    folder = run / state(run)["checkpoint"]
    assert folder.name == f"iter_{done:04d}" and not folder.name.endswith(".partial")
    assert {"protagonist.zip", "observation_adversary.zip"} <= {p.name for p in folder.iterdir()}
    pop = Population.load(run / "population.json")
    for m in pop.of("observation_adversary", learned_only=True):
        if m.iteration <= done:
            assert Path(m.spec.path).is_file(), m.spec.path
    assert {int(r["iteration"]) for r in progress_rows(run)} <= set(range(1, done + 2))

    assert main(["resume", str(run), "--no-progress"]) == 0
    assert state(run)["iteration"] == iterations
    assert [int(r["iteration"]) for r in progress_rows(run)] == list(range(1, iterations + 1))
    assert [int(r["protagonist_steps"]) for r in progress_rows(run)] == [
        128 * i for i in range(1, iterations + 1)
    ]
    names = sorted(p.name for p in (run / "checkpoints").iterdir())
    assert names == [f"iter_{i:04d}" for i in range(iterations + 1)]
    pop = Population.load(run / "population.json")
    ids = [m.id for m in pop]
    assert len(ids) == len(set(ids))
    assert ids == ["observation_adversary:noop"] + [
        f"observation_adversary@{i}" for i in range(iterations + 1)
    ]
    assert all(Path(m.spec.path).is_file() for m in pop if m.learned)


# -- population sampling ----------------------------------------------------------------------


def hand_built_population() -> Population:
    pop = Population()
    pop.add(Member(f"{AGENT}:noop", "adversary", AGENT, ZeroAdversary(), 0, learned=False))
    for i in range(4):
        pop.add(Member(f"{AGENT}@{i}", "adversary", AGENT, ConstantAdversary((0.1 * i,)), i))
    pop.add(Member("other@0", "adversary", "action_adversary", ZeroAdversary(), 0))
    return pop


def draws(how: str, n: int = 400, seed: int = 0) -> list[str]:
    pop, rng = hand_built_population(), np.random.default_rng(seed)
    return [pop.sample(AGENT, how, rng).id for _ in range(n)]


def test_latest_sampling_is_always_the_newest_member() -> None:
    assert set(draws("latest")) == {f"{AGENT}@3"}
    pop = hand_built_population()
    pop.add(Member(f"{AGENT}@4", "adversary", AGENT, ZeroAdversary(), 4))
    assert pop.sample(AGENT, "latest", np.random.default_rng(0)).id == f"{AGENT}@4"


def test_fictitious_sampling_never_draws_an_unlearned_member() -> None:
    counts = Counter(draws("fictitious"))
    assert set(counts) == {f"{AGENT}@{i}" for i in range(4)}  # every snapshot, never the no-op
    assert min(counts.values()) > 400 / 4 * 0.6


def test_uniform_sampling_covers_every_member_of_the_agent() -> None:
    counts = Counter(draws("uniform"))
    assert set(counts) == {f"{AGENT}:noop", *(f"{AGENT}@{i}" for i in range(4))}
    assert min(counts.values()) > 400 / 5 * 0.6


def test_sampling_is_reproducible_from_the_generator() -> None:
    assert draws("uniform", seed=7) == draws("uniform", seed=7)
    assert draws("uniform", seed=7) != draws("uniform", seed=8)


def test_sampling_errors_name_the_problem() -> None:
    pop, rng = hand_built_population(), np.random.default_rng(0)
    with pytest.raises(ConfigError, match="'best'"):
        pop.sample(AGENT, "best", rng)
    with pytest.raises(ConfigError, match="force_adversary"):
        pop.sample("force_adversary", "latest", rng)
    with pytest.raises(ConfigError, match="@0"):
        pop.add(Member(f"{AGENT}@0", "adversary", AGENT, ZeroAdversary(), 0))


def test_population_file_round_trip(tmp_path: Path) -> None:
    pop = hand_built_population()
    pop.save(tmp_path / "population.json")
    back = Population.load(tmp_path / "population.json")
    assert [m.to_dict() for m in back] == [m.to_dict() for m in pop]
    assert back.members[2].spec == ConstantAdversary((0.1,))


# -- config validation ------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("iterations", 0),
        ("iterations", 2.5),
        ("protagonist_steps", -128),
        ("adversary_steps", -1),
        ("warmup_steps", -64),
        ("eval_episodes", -1),
        ("n_envs", 0),
        ("snapshot_every", 0),
        ("sampling", "best-response"),
        ("train_budget_scale", 0.0),
        ("train_budget_scale", -0.5),
        ("train_budget_scale", "half"),
        ("vec_env", "subprocess"),
        ("protagonist_algo", "dqn"),
        ("adversary_algo", "a2c"),
        ("learned", "observation_adversary"),
    ],
)
def test_bad_train_config_values_raise_config_error(field: str, value: Any) -> None:
    with pytest.raises(ConfigError) as err:
        TrainConfig(**{field: value})
    assert repr(value) in str(err.value) or str(value) in str(err.value)
    assert field in str(err.value)


def test_unknown_learner_hyper_parameters_suggest_the_nearest_name(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match='Did you mean "n_steps"'):
        learner_config("ppo", {"n_step": 64})
    with pytest.raises(ConfigError, match='Did you mean "learning_starts"'):
        learner_config("sac", {"learning_start": 32})
    with pytest.raises(ConfigError, match="'n_steps'") as err:
        train(TrainConfig(adversary_hparams={"nsteps": 64}), tmp_path / "run", progress=False)
    assert "nsteps" in str(err.value)
    assert not (tmp_path / "run" / "state.json").exists()


def test_bad_learner_hyper_parameter_values_raise_config_error() -> None:
    with pytest.raises(ConfigError, match=r"n_steps.* 0\b"):
        learner_config("ppo", {"n_steps": 0})
    with pytest.raises(ConfigError, match=r"buffer_size.*-5"):
        learner_config("sac", {"buffer_size": -5})
    with pytest.raises(ConfigError, match="'mappo2'"):
        learner_config("mappo2", None)


def test_learned_must_name_adversaries_of_the_game(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="force_adversary"):
        train(config("atla", learned=["force_adversary"]), tmp_path / "run", progress=False)


def test_the_rollout_size_warning_names_only_sides_that_train(caplog, tmp_path: Path) -> None:
    """A whole-rollout mismatch is warned for each side that trains; PPO trains no adversary."""
    import logging

    from advgame.training.loop import Run
    from advgame.training.trainer import Trainer

    odd = {"n_steps": 48}  # TINY's phases are not whole rollouts of 48 steps
    for method, sides in (("ppo", {"protagonist"}), ("atla", {"protagonist", "adversary"})):
        caplog.clear()
        cfg = config(method, protagonist_hparams=odd, adversary_hparams=odd)
        with caplog.at_level(logging.WARNING, logger="advgame.training.loop"):
            Run(Trainer(cfg, tmp_path / method))
        warned = {s for s in ("protagonist", "adversary") if f"each {s} phase" in caplog.text}
        assert warned == sides, method
