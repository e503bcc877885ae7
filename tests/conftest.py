"""Fixtures shared by several test modules."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest


@pytest.fixture(autouse=True, scope="session")
def _cache_in_tmp(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Caches advgame writes (Robust Sarsa critics) go to a temporary folder, not ~/.cache."""
    before = os.environ.get("ADVGAME_CACHE")
    os.environ["ADVGAME_CACHE"] = str(tmp_path_factory.mktemp("advgame-cache"))
    yield
    if before is None:
        os.environ.pop("ADVGAME_CACHE", None)
    else:
        os.environ["ADVGAME_CACHE"] = before


@pytest.fixture
def one_torch_thread() -> Iterator[None]:
    """Run the test on one torch thread (as training workers do), then restore the count."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def pendulum_ppo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A PPO trained a little (4096 steps) with plain SB3 on InvertedPendulum-v5, no normalizer."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    path = tmp_path_factory.mktemp("pendulum") / "ppo.zip"
    env = gym.make("InvertedPendulum-v5")
    model = PPO("MlpPolicy", env, n_steps=512, batch_size=64, n_epochs=4, seed=0, device="cpu")
    model.learn(4096)
    model.save(path)
    env.close()
    torch.set_num_threads(before)
    return path


@pytest.fixture(scope="session")
def pendulum_pair(pendulum_ppo: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Two different InvertedPendulum-v5 victims (`pendulum_ppo` and an untrained PPO, seed 1)."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    from advgame.evaluation import sb3_protagonist

    other = tmp_path_factory.mktemp("pendulum-untrained") / "ppo.zip"
    PPO("MlpPolicy", gym.make("InvertedPendulum-v5"), seed=1, device="cpu").save(other)
    paths = {"a": pendulum_ppo, "b": other}
    return {n: sb3_protagonist(p, raw_observations=True) for n, p in paths.items()}


@pytest.fixture(scope="session")
def tiny_atla() -> Callable[..., list[str]]:
    """`advgame train` arguments of a tiny ATLA run on Hopper-v5 (128 steps a side, n_steps 64).

    Call it with the number of iterations (default 2); add ``--run-dir`` yourself.
    """

    def args(iterations: int = 2) -> list[str]:
        return [
            "--method", "atla", "--scenario", "Hopper-v5", "--iterations", str(iterations),
            "--protagonist-steps", "128", "--adversary-steps", "128", "--eval-episodes", "1",
            "--set", 'protagonist_hparams={"n_steps": 64}',
            "--set", 'adversary_hparams={"n_steps": 64}',
            "--no-progress",
        ]  # fmt: skip

    return args


# -- the module games of the disruptor property tests (tests/test_disruptors_*.py) ---------------
@pytest.fixture(scope="module")
def hopper():
    """Hopper-v5 with every disruptor kind under test (budgets in tests/_disruptor_helpers.py)."""
    import advgame
    from advgame.disruptors import (
        ActionDisruptor,
        DynamicsDisruptor,
        ForceDisruptor,
        ObservationDisruptor,
        RewardDisruptor,
    )
    from tests._disruptor_helpers import (
        ACT_EPS,
        DYN_PARAMS,
        FORCE_BOUNDS,
        OBS_EPS,
        TORQUE_BOUND,
    )

    game = advgame.make(
        "Hopper-v5",
        disruptors=[
            ObservationDisruptor(eps=tuple(OBS_EPS), name="obs_linf"),
            ObservationDisruptor(eps=0.2, norm="l2", name="obs_l2"),
            ObservationDisruptor(eps=0.1, space="normalized", name="obs_norm"),
            ObservationDisruptor(eps=0.3, dims=(0, 5, 7), name="obs_dims"),
            ObservationDisruptor(bounded=False, name="obs_unbounded"),
            RewardDisruptor(eps=0.5),
            RewardDisruptor(eps=0.25, signal="cost"),
            RewardDisruptor(bounded=False, name="reward_unbounded"),
            ActionDisruptor(eps=ACT_EPS, name="act_add"),
            ActionDisruptor(mode="probabilistic", alpha=0.5, name="act_prob"),
            ActionDisruptor(mode="noisy", alpha=0.3, name="act_noisy"),
            ActionDisruptor(bounded=False, name="act_unbounded"),
            ForceDisruptor(
                bodies=("torso", "foot"),
                axes="xz",
                max_force=FORCE_BOUNDS,
                torque_axes="y",
                max_torque=TORQUE_BOUND,
            ),
            DynamicsDisruptor(params=DYN_PARAMS),
        ],
    )
    game.reset(seed=0)
    yield game
    game.close()


@pytest.fixture(scope="module")
def hopper_obs(hopper):
    """The protagonist's first observation of `hopper` (seed 0), as float64."""
    import numpy as np

    from tests._disruptor_helpers import P

    obs, _ = hopper.reset(seed=0)
    return np.array(obs[P], dtype=np.float64)


@pytest.fixture(scope="module")
def lunar():
    """LunarLander-v3 with an observation and a discrete (probabilistic) action disruptor."""
    import advgame
    from advgame.disruptors import ActionDisruptor, ObservationDisruptor
    from tests._disruptor_helpers import BOX2D_REASON

    pytest.importorskip("Box2D", reason=BOX2D_REASON)
    game = advgame.make(
        "LunarLander-v3",
        disruptors=[
            ObservationDisruptor(eps=3.0),
            ActionDisruptor(mode="probabilistic", alpha=1.0, name="act_discrete"),
        ],
    )
    game.reset(seed=0)
    yield game
    game.close()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    """With ``ADVGAME_SKIP_MISSING_EXTRAS=1`` (the unlocked newest-Python run of CI, which
    installs the core package alone), a test stopped by `MissingExtraError` is reported as
    skipped, naming the extra. Without it, as in the locked run, such a test fails."""
    outcome = yield
    report = outcome.get_result()
    if os.environ.get("ADVGAME_SKIP_MISSING_EXTRAS") != "1" or call.excinfo is None:
        return
    from advgame.errors import MissingExtraError

    if call.excinfo.errisinstance(MissingExtraError) or call.excinfo.errisinstance(
        ModuleNotFoundError
    ):
        report.outcome = "skipped"
        report.longrepr = (
            str(item.path),
            item.location[1] or 0,
            f"extra missing: {call.excinfo.value}",
        )


CORE_FILES = frozenset(
    f"test_{name}.py"
    for name in (
        "game_moves", "game_payoffs_and_determinism", "game_errors", "views", "vector", "lockstep",
        "disruptors_observation_reward", "disruptors_action_force_dynamics", "disruptors_decode",
        "dynamics_params", "dynamics_schedules_force",
        "evaluation", "batched_eval", "evaluate_any", "threat_model", "policy_wrappers",
        "whitebox", "sb3", "training_run", "training_learners", "training_population_config", "cli",
        "not_applicable", "robust_sarsa", "attack_batch",
        "fuzz_config", "fuzz_train_eval", "corrupt_files", "sa_ppo", "pgd_at",
        "train_config_game", "mujoco_batch", "mujoco_lean", "native_step", "relay", "mujoco_timers",
    )
)  # fmt: skip
"""The modules of the core subset (marker ``core``): the game, its views and vector paths,
disruptors, evaluation, white-box attacks, SB3 training and the CLI. CI runs it again, unlocked,
on the newest Python pyenv has (`.ci/run`); so can you: ``pytest -m "core and not slow"``."""

CORE_FAMILIES = frozenset({"mujoco"})
"""Conformance cases in the core subset: Gymnasium's own MuJoCo tasks (no extra needed)."""


def _is_core(item: pytest.Item) -> bool:
    if item.path.name in CORE_FILES:
        return True
    if item.path.name != "test_conformance.py" or not hasattr(item, "callspec"):
        return False
    from advgame.core.registry import scenario_spec

    return scenario_spec(item.callspec.params["sid"]).family in CORE_FAMILIES


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark the core subset ``core`` (see `CORE_FILES`)."""
    for item in items:
        if _is_core(item):
            item.add_marker(pytest.mark.core)
