"""Wrappers of white-box policies (evaluation's timing wrapper, PSRO's mixtures) are white-box
on every Python: since 3.12, ``isinstance(x, WhiteBox)`` looks methods up statically, so a
forwarding ``__getattr__`` is not enough. The checks here use that static lookup on any Python."""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np
import pytest
import torch

import advgame
from advgame.adversaries.whitebox import MADAttack
from advgame.core.episodes import rollout
from advgame.core.policy import WhiteBox
from advgame.disruptors import ObservationDisruptor
from advgame.evaluation.table.jobs import EvalJob
from advgame.evaluation.table.running import _ClockedSpec, run_unit
from advgame.training.best_response import MixtureSpec

ADV = "observation_adversary"
WHITEBOX_METHODS = ("action_mean", "action_std", "value", "q_value")


class LinearVictim:
    """A differentiable protagonist: a = tanh(W s), V(s) = sin(v·s), std 0.5."""

    def __init__(self, seed: int) -> None:
        gen = torch.Generator().manual_seed(seed)
        self.w = 0.2 * torch.randn(3, 11, generator=gen)
        self.v = torch.randn(11, generator=gen)

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, observation: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            obs = torch.as_tensor(np.asarray(observation, dtype=np.float32))[None]
            return self.action_mean(obs)[0].numpy()

    def action_mean(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.tanh(obs @ self.w.T)

    def action_std(self) -> torch.Tensor:
        return torch.full((3,), 0.5)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.sin(obs @ self.v)

    def q_value(self, obs: torch.Tensor, action: torch.Tensor) -> None:
        return None


def statically_whitebox(obj: Any) -> bool:
    """What Python >= 3.12's ``isinstance(obj, WhiteBox)`` checks, on this Python too."""
    return all(callable(inspect.getattr_static(obj, m, None)) for m in WHITEBOX_METHODS)


def black_box(observation: np.ndarray) -> np.ndarray:
    return np.zeros(3, dtype=np.float32)


@pytest.fixture
def info() -> Any:
    return advgame.make("Hopper-v5").agent_info("protagonist")


def _wrappers(inner: list[Any]) -> list[Any]:
    """The timing wrapper of the first policy and a mixture of all of them."""
    return [_ClockedSpec(inner[0]), MixtureSpec(tuple(inner), (1 / len(inner),) * len(inner))]


@pytest.mark.parametrize("which", ["clocked", "mixture"])
def test_a_wrapped_white_box_policy_is_a_white_box_that_answers_as_it_does(
    which: str, info: Any
) -> None:
    victims = [LinearVictim(0), LinearVictim(1)]
    spec = dict(zip(["clocked", "mixture"], _wrappers(victims), strict=True))[which]
    wrapped = spec.build(info)
    assert statically_whitebox(wrapped) and isinstance(wrapped, WhiteBox)
    wrapped.reset(seed=3)
    inner = wrapped.wrapped
    assert inner in victims
    obs = torch.randn(4, 11, generator=torch.Generator().manual_seed(0))
    assert torch.equal(wrapped.action_mean(obs), inner.action_mean(obs))
    assert torch.equal(wrapped.value(obs), inner.value(obs))
    assert torch.equal(wrapped.action_std(), inner.action_std())
    assert wrapped.q_value(obs, wrapped.action_mean(obs)) is None


@pytest.mark.parametrize("which", ["clocked", "mixture"])
def test_a_wrapped_black_box_policy_is_not_a_white_box(which: str, info: Any) -> None:
    inner = [black_box] if which == "clocked" else [black_box, LinearVictim(0)]
    spec = dict(zip(["clocked", "mixture"], _wrappers(inner), strict=True))[which]
    wrapped = spec.build(info)
    assert not statically_whitebox(wrapped) and not isinstance(wrapped, WhiteBox)


@pytest.mark.usefixtures("one_torch_thread")
def test_a_timed_evaluation_unit_plays_mad_as_the_plain_rollout_does() -> None:
    make_kwargs = {"disruptors": [ObservationDisruptor(eps=0.1)], "max_episode_steps": 12}
    job = EvalJob(
        scenario="Hopper-v5",
        make_kwargs=make_kwargs,
        protagonist="linear",
        protagonist_spec=LinearVictim(0),
        adversary="mad",
        adversary_specs={ADV: MADAttack(steps=3)},
        seeds=(0,),
    )
    [row] = run_unit(job)  # the protagonist is played behind the timing wrapper
    game = advgame.make("Hopper-v5", phase="eval", **make_kwargs)
    [alone] = rollout(game, {"protagonist": LinearVictim(0), ADV: MADAttack(steps=3)}, seed=0)
    [nominal] = rollout(game, {"protagonist": LinearVictim(0)}, seed=0)
    assert row["true_return"] == pytest.approx(alone.true_return, rel=1e-9)
    assert alone.true_return != nominal.true_return  # the attack did something
