"""Batched evaluation on arrays: `rollout_batch`'s array path gives the lockstep path's results.

The same episodes (same seeds, freshly built games and policies) are played three ways:
`rollout_batch` with the array path (`advgame.core.array_rollout`), `rollout_batch` with it
switched off (``USE_ARRAYS = False``: the lockstep path), and one `rollout` per episode alone;
every `EpisodeResult` field must be equal, value and type. Policies draw from their own seeded
generators, adversaries' actions partly outside the box (so clips count), protagonists'
actions depend on what they are shown (so observation perturbations change the episode).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pytest

import advgame
from advgame.core import array_rollout
from advgame.core.episodes import EpisodeResult, build_policies, rollout, rollout_batch
from advgame.disruptors import ActionDisruptor, ObservationDisruptor
from tests._disruptor_helpers import split_schedules

Make = Callable[[], advgame.Game]
Policies = Callable[[advgame.Game], dict[str, Any]]


class _Wild:
    """An adversary drawing from its own generator, partly outside its box (clips count)."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.shape, self.rng = shape, np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def act(self, observation: Any) -> np.ndarray:
        return self.rng.uniform(-1.25, 1.25, self.shape)


class _Jumpy:
    """A protagonist acting on what it is shown, plus noise of `scale` from its own generator."""

    def __init__(self, size: int, scale: float) -> None:
        self.size, self.scale, self.rng = size, scale, np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def act(self, observation: Any) -> np.ndarray:
        noise = self.rng.uniform(-self.scale, self.scale, self.size)
        return np.clip(np.tanh(observation[: self.size]) + noise, -1, 1).astype(np.float32)


class _Net:
    """A deterministic protagonist with a batch key: its copies are asked at once (`act_batch`)."""

    batch_key = "net"
    calls: list[int] = []  # noqa: RUF012  # rows per batched call, over all instances

    def __init__(self, size: int, std: np.ndarray | None = None) -> None:
        self.size = size
        if std is not None:
            self.observation_std = std

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, observation: Any) -> np.ndarray:
        return np.tanh(2.0 * observation[: self.size]).astype(np.float32)

    def act_batch(self, observations: np.ndarray) -> np.ndarray:
        _Net.calls.append(len(observations))
        return np.tanh(2.0 * observations[:, : self.size]).astype(np.float32)


def _wild(game: advgame.Game, protagonist: Any) -> dict[str, Any]:
    out = {a: _Wild(game.action_space(a).shape) for a in game.adversaries}
    return {**out, "protagonist": protagonist}


def _jumpy(scale: float) -> Policies:
    return lambda g: _wild(g, _Jumpy(g.action_space("protagonist").shape[0], scale))


def _net(g: advgame.Game) -> dict[str, Any]:
    return _wild(g, _Net(g.action_space("protagonist").shape[0]))


def _batch(
    makes: Sequence[Make], policies: Policies, seeds: Sequence[int]
) -> tuple[list[EpisodeResult], list[tuple[Any, ...]]]:
    """`rollout_batch`'s results, and what each game holds at the end."""
    games = [make() for make in makes]
    out = rollout_batch(games, [build_policies(g, policies(g)) for g in games], seeds)
    ends = [(g.t, g.agents, g.last_reward, g.episode_reward, g.state().tolist()) for g in games]
    return out, ends


def _three_ways(
    makes: Sequence[Make], policies: Policies, seeds: Sequence[int], monkeypatch: Any
) -> tuple[list[EpisodeResult], list[list[int]]]:
    """Play the episodes on arrays, in lockstep and one by one; assert all equal.

    Returns the array path's results and the groups it played on arrays.
    """
    groups: list[list[list[int]]] = []
    find = array_rollout.array_groups

    def spy(*args: Any) -> list[list[int]]:
        groups.append(find(*args))
        return groups[-1]

    monkeypatch.setattr(array_rollout, "array_groups", spy)
    arrays, ends = _batch(makes, policies, seeds)
    with monkeypatch.context() as m:
        m.setattr(array_rollout, "USE_ARRAYS", False)
        lockstep, want_ends = _batch(makes, policies, seeds)
    assert ends == want_ends
    alone = [
        rollout(make(), policies(make()), seed=s)[0] for make, s in zip(makes, seeds, strict=True)
    ]
    want = [_typed(r) for r in alone]
    assert [_typed(r) for r in lockstep] == want
    assert [_typed(r) for r in arrays] == want
    return arrays, groups[0]


def _typed(r: EpisodeResult) -> list[tuple[str, Any, type]]:
    fields = dataclasses.asdict(r)
    out = [(k, v, type(v)) for k, v in fields.items() if k != "clipped"]
    return out + [(a, n, type(n)) for a, n in r.clipped.items()]


def _game(scenario: str, steps: int, **kwargs: Any) -> Make:
    return lambda: advgame.make(scenario, max_episode_steps=steps, **kwargs)


def test_half_cheetah_plays_whole_episodes_on_arrays(monkeypatch: pytest.MonkeyPatch) -> None:
    """No terminations: every step on arrays (observation and action adversaries)."""
    make = _game("HalfCheetah-v5", 60, preset="default")
    out, groups = _three_ways([make] * 4, _jumpy(0.3), range(4), monkeypatch)
    assert groups == [[0, 1, 2, 3]]
    assert [r.length for r in out] == [60] * 4
    assert all(r.clipped["observation_adversary"] > 0 for r in out)
    assert len({r.true_return for r in out}) == 4


def test_hopper_episodes_that_end_apart(monkeypatch: pytest.MonkeyPatch) -> None:
    """Terminations at different steps: arrays until the first, then lockstep."""
    make = _game("Hopper-v5", 300, preset="default")
    out, groups = _three_ways([make] * 5, _jumpy(1.0), range(5), monkeypatch)
    assert groups == [[0, 1, 2, 3, 4]]
    assert len({r.length for r in out}) > 2
    assert any(r.terminated for r in out)


def test_dynamics_force_and_reward_adversaries(monkeypatch: pytest.MonkeyPatch) -> None:
    """Preset ``full``: observation, reward, action, dynamics and force adversaries."""
    make = _game("Hopper-v5", 80, preset="full")
    out, groups = _three_ways([make] * 3, _jumpy(0.5), range(3), monkeypatch)
    assert groups == [[0, 1, 2]]
    assert all(r.true_return != r.observed_return for r in out)  # the reward adversary acted


def test_schedules_that_split_the_copies(monkeypatch: pytest.MonkeyPatch) -> None:
    """Probabilistic, every-n, held and stale perturbations: movers differ between copies."""
    spec = split_schedules()
    make = _game("Walker2d-v5", 120, disruptors=spec)
    _, groups = _three_ways([make] * 4, _jumpy(0.6), range(10, 14), monkeypatch)
    assert groups == [[0, 1, 2, 3]]


def test_normalized_budgets_and_a_batched_network(monkeypatch: pytest.MonkeyPatch) -> None:
    """A protagonist exposing ``observation_std`` scales the budget; its copies asked at once."""
    spec = [ObservationDisruptor(eps=0.1, space="normalized"), ActionDisruptor(alpha=0.2)]
    make = _game("Hopper-v5", 120, disruptors=spec)
    std = np.linspace(0.5, 2.0, 11)
    _Net.calls.clear()
    _, groups = _three_ways([make] * 4, lambda g: _wild(g, _Net(3, std)), range(4), monkeypatch)
    assert groups == [[0, 1, 2, 3]]
    assert 4 in _Net.calls  # one call for the four copies
    built = iter(range(1000))  # game k of each way: std 1 + k % 3

    def apart(g: advgame.Game) -> dict[str, Any]:
        return _wild(g, _Net(3, np.full(11, 1.0 + next(built) % 3)))

    _, groups = _three_ways([make] * 6, apart, range(6), monkeypatch)
    assert groups == [[0, 3], [1, 4], [2, 5]]  # one group per scale


def test_mixed_setups_play_as_one_array_each(monkeypatch: pytest.MonkeyPatch) -> None:
    """A table's columns in one call: each alike group on its own array, a lone game in lockstep."""
    makes = [
        _game("Hopper-v5", 150, preset="default"),
        _game("Hopper-v5", 150, preset="full"),
        _game("Hopper-v5", 150, preset="default"),
        _game("Hopper-v5", 150, preset="action-gauss-0.1"),
        _game("Hopper-v5", 150, preset="full"),
        _game("Hopper-v5", 150, preset="default"),
    ]
    _Net.calls.clear()
    _, groups = _three_ways(makes, _net, range(6), monkeypatch)
    assert groups == [[0, 2, 5], [1, 4]]
    assert 5 in _Net.calls  # the network asked once for both groups' copies


def test_box2d_and_game_bound_policies_fall_back(monkeypatch: pytest.MonkeyPatch) -> None:
    """Box2D cannot batch its simulators, a policy bound to its game reads it: lockstep."""
    make = _game("LunarLanderContinuous-v3", 60, preset="default")
    _, groups = _three_ways([make] * 3, _jumpy(0.5), range(3), monkeypatch)
    assert groups == []

    class Bound(_Jumpy):
        game = "a game"

    make = _game("Hopper-v5", 40, preset="default")
    _, groups = _three_ways([make] * 2, lambda g: _wild(g, Bound(3, 0.5)), range(2), monkeypatch)
    assert groups == []
