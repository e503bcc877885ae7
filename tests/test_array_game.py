"""`advgame.core.array_game.ArrayGame`: every copy plays bit for bit as its single game.

N single games and one array game of N copies play the same random actions from the same
seeds (adversary actions partly outside the box, so clips count): every shown observation,
true state, observed and true reward and cost, payoff, ending, info term, per-move clip count
and per-episode clip count must be equal (``np.testing.assert_array_equal``), across resets
(copies end at different steps and reset with ``seed=None``, continuing their generators),
on every MuJoCo v5 and Safety task, with every disruptor kind, per-step schedules (every
``n``, probabilities, held and stale perturbations), L2 budgets, the probabilistic action mode
and normalized-space budgets. Box2D cannot batch: it falls back, says so, and is still exact.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from gymnasium.spaces import Box

import advgame
from advgame.core.array_game import ArrayGame, ArrayStep, unsupported
from advgame.core.game import Move
from advgame.core.moves import SENSE
from advgame.disruptors import ActionDisruptor, ObservationDisruptor, RewardDisruptor
from advgame.errors import ActionError, ConfigError
from tests._disruptor_helpers import split_schedules

N = 3
MUJOCO = advgame.list_scenarios(family="mujoco")
SAFE = advgame.list_scenarios(family="safe")


def _box(game: advgame.Game, agent: str, rng: np.random.Generator) -> np.ndarray:
    space = game.action_space(agent)
    assert isinstance(space, Box)
    if agent in game.protagonists:
        return rng.uniform(space.low, space.high, (N, *space.shape)).astype(space.dtype)
    return rng.uniform(-1.25, 1.25, (N, *space.shape))  # some components clip


def play_both(make: Callable[[], advgame.Game], steps: int, seed: int = 0) -> ArrayGame:
    """Play `steps` moves of N single games and of one array game; assert every value equal."""
    singles = [make() for _ in range(N)]
    array = ArrayGame([make() for _ in range(N)])
    for i, g in enumerate(singles):
        g.reset(seed=seed + i)
    array.reset(seed=seed)
    rng = np.random.default_rng(seed)
    g0 = singles[0]
    sensing = [d.agent for d in g0._sensing]
    movers = [*g0.protagonists, *(d.agent for d in g0._act_ds)]
    for _ in range(steps):
        _same_view(singles, array)
        sense = {a: _box(g0, a, rng) for a in sensing}
        np.testing.assert_array_equal(array.sensing(), [g.move == SENSE for g in singles])
        array.sense(sense)
        for i, g in enumerate(singles):
            if g.move == SENSE:
                g.play({a: sense[a][i] for a in sensing})
            for a in sensing:
                assert g.disruptors[a].clip_count == array.clip_count[a][i], a
        _same_view(singles, array)
        acts = {a: _box(g0, a, rng) for a in movers}
        step = array.act(acts)
        for i, g in enumerate(singles):
            m = g.play({a: acts[a][i] for a in movers})
            _same_move(m, step, i)
            for a in g.adversaries:
                assert g.disruptors[a].clip_count == array.clip_count[a][i], a
        if array.done.any():
            for i in np.flatnonzero(array.done):
                singles[i].reset(seed=None)
            array.reset(seed=None, rows=array.done)
    return array


def _same_view(singles: list[advgame.Game], array: ArrayGame) -> None:
    for i, g in enumerate(singles):
        for p in g.protagonists:
            np.testing.assert_array_equal(array.observe(p)[i], g.observe(p))
            assert array.observe(p)[i].dtype == np.asarray(g.observe(p)).dtype
        np.testing.assert_array_equal(array.state()[i], g.state())


def _same_move(m: Move, step: ArrayStep, i: int) -> None:
    assert m.rewards is not None and m.costs is not None and m.info is not None
    for p in m.rewards:
        assert m.rewards[p] == step.rewards[p][i] and m.costs[p] == step.costs[p][i]
    assert (m.reward, m.cost, m.payoff) == (step.reward[i], step.cost[i], step.payoff[i])
    assert (m.terminated, m.truncated) == (step.terminated[i], step.truncated[i])
    for key, value in m.info.items():
        np.testing.assert_array_equal(step.info[key][i], value, err_msg=key)
    for a, count in step.clipped.items():
        assert m.clipped.get(a, 0) == count[i], a
        assert (a in m.clipped) == step.acted[a][i], a


def _game(scenario: str, **kwargs: Any) -> Callable[[], advgame.Game]:
    return lambda: advgame.make(scenario, max_episode_steps=25, **kwargs)


@pytest.mark.parametrize("scenario", MUJOCO + SAFE)
def test_every_batched_task_default(scenario: str) -> None:
    """Observation, action (and on safe tasks observed-cost) adversaries, 60 moves."""
    play_both(_game(scenario, preset="default"), steps=60)


@pytest.mark.parametrize("scenario", ["Hopper-v5", "Walker2d-v5", "SafetyHopper-v5"])
def test_every_disruptor_kind(scenario: str) -> None:
    """Preset ``full``: observation, reward, action, per-episode dynamics and forces."""
    play_both(_game(scenario, preset="full"), steps=80)


def test_schedules_held_and_stale() -> None:
    """Probabilistic, every-n, held and stale perturbations split the copies step by step."""
    spec = split_schedules()
    play_both(_game("Hopper-v5", disruptors=spec), steps=90)


def test_l2_budget_and_probabilistic_actions() -> None:
    """L2 projections row by row; the probabilistic mode draws from each copy's generator."""
    spec = [
        ObservationDisruptor(eps=0.2, norm="l2", dims=[0, 2, 5]),
        ActionDisruptor(mode="probabilistic", alpha=0.5),
        RewardDisruptor(eps=0.3),
    ]
    play_both(_game("Walker2d-v5", disruptors=spec), steps=80)


def test_noisy_actions_and_some_observation_dimensions() -> None:
    """The noisy mode's float64 mix of float32 actions and δ on a few dimensions, as one game's."""
    spec = [
        ObservationDisruptor(eps=0.2, dims=[4, 1, 7]),
        ActionDisruptor(mode="noisy", alpha=0.3),
    ]
    play_both(_game("HalfCheetah-v5", disruptors=spec), steps=60)


def test_normalized_budget() -> None:
    """A normalized-space budget scaled on every copy equals the single games scaled alike."""
    std = np.linspace(0.5, 2.0, 11)

    def make() -> advgame.Game:
        game = _game("Hopper-v5", disruptors=[ObservationDisruptor(eps=0.1, space="normalized")])()
        game.set_observation_scale("protagonist", std)
        return game

    play_both(make, steps=50)


def test_box2d_falls_back_visibly(caplog: pytest.LogCaptureFixture) -> None:
    """Box2D cannot batch its simulators: the copies step one by one, logged, still exact."""
    from advgame.core import array_game

    array_game._LOGGED.clear()
    with caplog.at_level(logging.WARNING, logger="advgame.core.array_game"):
        array = play_both(_game("LunarLanderContinuous-v3", preset="default"), steps=40)
    assert not array._task_type.batched
    assert "cannot batch its simulators" in caplog.text


def test_refuses_what_it_cannot_play() -> None:
    """Unlike games, or bad actions, are errors that say why."""
    games = [advgame.make("Hopper-v5", preset="default"), advgame.make("Hopper-v5", disruptors=[])]
    assert unsupported(games) is not None
    with pytest.raises(ConfigError, match="not alike"):
        ArrayGame(games)
    array = ArrayGame([advgame.make("Hopper-v5", preset="default") for _ in range(2)])
    with pytest.raises(ActionError, match="reset"):
        array.act({})
    array.reset(seed=0)
    with pytest.raises(ActionError, match="shape"):
        array.sense({"observation_adversary": np.zeros((3, 11))})
    with pytest.raises(ActionError, match="Copy 1"):
        array.sense({"observation_adversary": np.array([np.zeros(11), np.full(11, np.nan)])})


def test_vector_view_swaps_policies_mid_episode() -> None:
    """New embedded policies mid-episode (the alternation loop's swap) keep every step exact."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from advgame.adversaries import ConstantAdversary, GaussianAdversary
    from advgame.core.vector import VectorView
    from advgame.core.views import view_factory

    noise = {"observation_adversary": GaussianAdversary(std=0.05)}
    fns = [view_factory("Hopper-v5", "protagonist", noise, preset="default")] * N
    array, dummy = VectorView(fns), DummyVecEnv(fns)
    assert array._array is not None
    array.seed(3)
    dummy.seed(3)
    np.testing.assert_array_equal(array.reset(), dummy.reset())
    rng = np.random.default_rng(0)
    for k in range(60):
        if k == 20:  # swap, then continue on the lockstep-free array path again
            new = {"action_adversary": ConstantAdversary([0.05, -0.2, 0.1])}  # clips
            array.env_method("set_policies", new)
            dummy.env_method("set_policies", new)
            assert array._array is not None
        actions = rng.uniform(-1, 1, (N, 3)).astype(np.float32)
        a, b = array.step(actions), dummy.step(actions)
        for x, y in zip(a[:3], b[:3], strict=True):
            np.testing.assert_array_equal(x, y)
        for ia, ib in zip(a[3], b[3], strict=True):
            assert ia.keys() == ib.keys()
            for key in ia:
                np.testing.assert_array_equal(ia[key], ib[key], err_msg=key)


def test_vector_view_with_adversaries_acting_on_some_copies_only() -> None:
    """The array path asks each embedded policy for the copies where it moves (some of them,
    under probabilistic and periodic schedules) and plays what DummyVecEnv's views play."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from advgame.core.vector import VectorView
    from advgame.core.views import view_factory

    policies = {d.agent: _EchoSpec() for d in split_schedules()}
    fns = [
        view_factory(
            "Hopper-v5", "protagonist", policies, disruptors=split_schedules(), max_episode_steps=25
        )
    ] * N
    array, dummy = VectorView(fns), DummyVecEnv(fns)
    assert array._array is not None  # the array path, not lockstep
    array.seed(5)
    dummy.seed(5)
    np.testing.assert_array_equal(array.reset(), dummy.reset())
    rng = np.random.default_rng(1)
    for _ in range(60):  # episodes of 25 steps: resets too
        actions = rng.uniform(-1, 1, (N, 3)).astype(np.float32)
        a, b = array.step(actions), dummy.step(actions)
        for x, y in zip(a[:3], b[:3], strict=True):
            np.testing.assert_array_equal(x, y)
        for ia, ib in zip(a[3], b[3], strict=True):
            assert ia.keys() == ib.keys()
            for key in ia:
                np.testing.assert_array_equal(ia[key], ib[key], err_msg=key)


class _Echo:
    """An adversary whose action is a function of what it observes: which rows it is asked
    for, and with which observations, shows in every move."""

    def __init__(self, size: int) -> None:
        self.size = size

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, observation: Any) -> np.ndarray:
        return np.tanh(3.0 * np.resize(np.asarray(observation, np.float64), self.size)) * 1.2


class _EchoSpec:
    """Builds an `_Echo` of the agent's action size (picklable, as view factories need)."""

    def build(self, info: Any) -> _Echo:
        return _Echo(int(np.prod(info.action_space.shape)))
