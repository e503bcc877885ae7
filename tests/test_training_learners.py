"""The alternation loop with every learner and method, and kill-and-resume: real SB3 learners on
real MuJoCo tasks, tiny sizes.

A TD3 protagonist with a warm-up under method "ppo", RARL with SAC on both sides (trained at half
the force bound, evaluated at the full one), ATLA with a TD3 protagonist and a SAC adversary, and
a run killed by SIGKILL through the installed ``advgame`` script that resumes to the end.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import advgame.core.registry
import advgame.training.loop
from advgame.agents.common.checkpoint import _algo_class
from advgame.cli import main
from advgame.core.episodes import rollout
from advgame.training import train
from advgame.training.population import Population
from tests._training_helpers import (
    HOPPER,
    OFF_POLICY,
    PENDULUM,
    config,
    final_learning_rate,
    final_protagonist,
    parameters,
    progress_rows,
    same_parameters,
    state,
)


def advgame_script() -> str:
    script = Path(sys.executable).with_name("advgame")
    found = script if script.exists() else shutil.which("advgame")
    assert found, "the `advgame` console script is not installed next to this interpreter"
    return str(found)


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


def test_the_learning_rate_decays_to_zero_over_a_run_with_warmup(td3_warmup_run: Path) -> None:
    # 64 warm-up + 2 x 128 steps were trained; the decay must span exactly those 320 steps
    assert final_learning_rate(td3_warmup_run, "td3") == pytest.approx(0.0, abs=1e-12)


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
