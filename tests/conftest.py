"""Fixtures shared by several test modules."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest


@pytest.fixture
def one_torch_thread() -> Iterator[None]:
    """Run the test on one torch thread (as training workers do), then restore the count."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


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


CORE_FILES = frozenset(
    f"test_{name}.py"
    for name in (
        "game", "views", "vector", "lockstep", "disruptors", "dynamics",
        "evaluation", "batched_eval", "evaluate_any", "threat_model", "policy_wrappers",
        "whitebox", "sb3", "training", "cli",
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
