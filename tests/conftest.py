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
