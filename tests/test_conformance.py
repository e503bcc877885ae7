"""Conformance of every registered scenario and preset, straight from the registry.

For each (scenario id, preset) pair the registry offers (the default suite runs a covering set,
`DEFAULT_RUN`: every scenario and every preset at least once; ``-m slow`` runs every pair):

* PettingZoo's own `parallel_api_test` and `parallel_seed_test`, with every warning an error;
* the project's game checks: spaces are cached objects, adversaries have `Box` action spaces,
  ``infos[agent]["acted"]`` agrees with `Game.next_movers`, payoffs are zero-sum on the *true*
  payoff, and two games reset with the same seed replay the same episode move by move (PettingZoo's
  `parallel_seed_test` stops after the first move, so the full-episode comparison is ours).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo.test import parallel_api_test, parallel_seed_test

import advgame
from advgame.core.registry import scenario_spec

SLOW = {"CarRacing-v3"}
"""Scenarios whose reset is expensive (CarRacing builds a track): fewer cycles."""

SHORT_FAMILIES = {"robosuite", "maze", "fetch", "hand", "adroit", "kitchen"}
"""Families whose steps are slow (robosuite: ~4-100 ms a step; gymnasium-robotics: 0.3-3 ms,
many ids): short horizons in these tests."""


def _needs_extra(sid: str) -> pytest.MarkDecorator:
    """Skips the cases of a scenario whose extra is not installed (e.g. an unlocked install)."""
    spec = scenario_spec(sid)
    reason = f"{sid} needs the {spec.extra} extra ({', '.join(spec.missing())} not installed)"
    return pytest.mark.skipif(bool(spec.missing()), reason=reason)


def _default_run() -> set[tuple[str, str]]:
    """The (scenario, preset) cases of the default suite; every other pair runs under ``-m slow``.

    Each scenario with its ``full`` preset (every disruptor kind its family has, on that task),
    and each preset name of a family once, on the family's scenarios in turn: every scenario and
    every disruptor set-up goes through all four checks by default, the cross product nightly.
    """
    families: dict[str, list[str]] = {}
    for sid in advgame.list_scenarios():
        families.setdefault(scenario_spec(sid).family, []).append(sid)
    chosen = set()
    for sids in families.values():
        presets = {sid: scenario_spec(sid).load_presets() for sid in sids}
        chosen |= {(sid, "full" if "full" in presets[sid] else "default") for sid in sids}
        for j, name in enumerate(sorted({n for p in presets.values() for n in p})):
            if not any((sid, name) in chosen for sid in sids):
                turn = sids[j % len(sids) :] + sids[: j % len(sids)]
                chosen.add((next(sid for sid in turn if name in presets[sid]), name))
    return chosen


DEFAULT_RUN = _default_run()
CASES = [
    pytest.param(
        sid,
        name,
        id=f"{sid}:{name}",
        marks=[_needs_extra(sid)] + ([] if (sid, name) in DEFAULT_RUN else [pytest.mark.slow]),
    )
    for sid in advgame.list_scenarios()
    for name in scenario_spec(sid).load_presets()
]


def _short(sid: str) -> bool:
    return sid in SLOW or scenario_spec(sid).family in SHORT_FAMILIES


def _cycles(sid: str) -> int:
    """Moves per episode in PettingZoo's tests."""
    return 20 if scenario_spec(sid).family in SHORT_FAMILIES else 30 if sid in SLOW else 200


def _episode_steps(sid: str) -> int:
    """Protagonist steps per episode in the game checks (a truncation horizon for the task)."""
    return 10 if _short(sid) else 40


def _assert_same(a: Any, b: Any, where: str) -> None:
    """Exact, recursive equality of two step outputs (dicts, arrays, scalars)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), (
            f"{where}: keys {a.keys()} != {b.keys()}"
        )
        for k in a:
            _assert_same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (tuple, list)):
        assert type(a) is type(b) and len(a) == len(b), f"{where}: {a!r} != {b!r}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a_arr, b_arr = np.asarray(a), np.asarray(b)
        assert a_arr.dtype == b_arr.dtype, f"{where}: dtype {a_arr.dtype} != {b_arr.dtype}"
        assert np.array_equal(a_arr, b_arr), f"{where}: {a_arr} != {b_arr}"
    else:
        assert type(a) is type(b) and a == b, f"{where}: {a!r} != {b!r}"


def _seed_spaces(game: advgame.Game, seed: int) -> None:
    for i, agent in enumerate(game.possible_agents):
        game.action_space(agent).seed(seed + i)


@pytest.mark.parametrize(("sid", "preset"), CASES)
def test_pettingzoo_parallel_api(sid: str, preset: str) -> None:
    game = advgame.make(sid, preset=preset)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            parallel_api_test(game, num_cycles=_cycles(sid))
    finally:
        game.close()


@pytest.mark.parametrize(("sid", "preset"), CASES)
def test_pettingzoo_parallel_seed(sid: str, preset: str) -> None:
    # Build one game first: importing Box2D's SWIG module emits DeprecationWarnings (third-party,
    # at import time only), and turning those into errors mid-import crashes the interpreter.
    advgame.make(sid, preset=preset).close()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parallel_seed_test(lambda: advgame.make(sid, preset=preset), num_cycles=_cycles(sid))


@pytest.mark.parametrize(("sid", "preset"), CASES)
def test_spaces_cached_and_adversaries_bounded_boxes(sid: str, preset: str) -> None:
    game = advgame.make(sid, preset=preset)
    spec = scenario_spec(sid).load_presets()[preset]
    assert game.adversaries == tuple(d.agent for d in spec.disruptors)
    assert game.possible_agents == [*game.protagonists, *game.adversaries]
    for agent in game.possible_agents:
        assert game.observation_space(agent) is game.observation_space(agent)
        assert game.action_space(agent) is game.action_space(agent)
    for agent in game.adversaries:
        space = game.action_space(agent)
        assert isinstance(space, spaces.Box), f"{agent}: {space}"
        disruptor = game.disruptors[agent]
        if disruptor.bounded:  # the budget lives in the disruptor; the action is normalized
            assert np.all(space.low == -1.0) and np.all(space.high == 1.0), f"{agent}: {space}"
        # adversaries observe the true state
        assert game.observation_space(agent) is game.state_space
    game.close()


def _setup_move(game: advgame.Game, movers: frozenset[str]) -> bool:
    """Whether `movers` are reset-time adversaries alone (they move first, once, at t = 0)."""
    return all(getattr(game.disruptors[a], "at_reset", False) for a in movers)


def _play_checked(game: advgame.Game, seed: int, horizon: int) -> list[tuple]:
    """One episode of random actions, checking zero-sum payoffs and `acted` on every move.

    Returns every move's outputs, for the determinism comparison.
    """
    obs, infos = game.reset(seed=seed)
    _seed_spaces(game, seed)
    moves: list[tuple] = [(obs, infos)]
    act_moves = setups = 0
    while game.agents:
        movers = game.next_movers
        assert movers, "a live game must say whose action the next move uses"
        assert movers <= set(game.agents)
        sense = not any(p in movers for p in game.protagonists)
        if sense and game.t == 0 and _setup_move(game, movers):
            setups += 1  # the setup move: only workspace (reset-time) adversaries, first, once
            assert setups == 1 and len(moves) == 1, "one setup move, the episode's first"
        elif sense:  # only observation adversaries move on a sense move
            assert all(game.disruptors[a].hook == "observation" for a in movers), movers
        else:
            assert set(game.protagonists) <= movers
        t = game.t
        actions = {a: game.action_space(a).sample() for a in game.agents}
        obs, rewards, terms, truncs, infos = game.step(actions)
        moves.append((obs, rewards, terms, truncs, infos))
        assert set(obs) == set(rewards) == set(terms) == set(truncs) == set(infos)
        assert set(infos) == set(game.possible_agents)
        for agent in game.possible_agents:
            assert infos[agent]["acted"] == (agent in movers), (agent, movers, infos[agent])
        if sense:
            assert game.t == t
            for agent in game.possible_agents:
                assert rewards[agent] == 0.0
            continue
        act_moves += 1
        assert game.t == t + 1
        for p in game.protagonists:
            info = infos[p]
            assert info["payoff"] == info["true_reward"] - game.cost_weight * info["true_cost"]
        payoff = infos[game.protagonists[0]]["payoff"]
        assert all(infos[p]["payoff"] == payoff for p in game.protagonists)  # one team payoff
        for adversary in game.adversaries:
            assert rewards[adversary] == -payoff, (adversary, rewards[adversary], payoff)
    assert 0 < act_moves <= horizon
    assert game.t == act_moves
    return moves


@pytest.mark.parametrize(("sid", "preset"), CASES)
def test_zero_sum_acted_and_full_episode_determinism(sid: str, preset: str) -> None:
    horizon = _episode_steps(sid)
    games = [advgame.make(sid, preset=preset, max_episode_steps=horizon) for _ in range(2)]
    # a schedule tied to one phase makes the other phase a different game: play both then
    phase_bound = any(d.schedule.phase != "both" for d in games[0].disruptors.values())
    for phase in ("train", "eval") if phase_bound else ("train",):
        for game in games:
            game.phase = phase
        first, second = (_play_checked(g, 7, horizon) for g in games)
        assert len(first) == len(second)
        for i, (a, b) in enumerate(zip(first, second, strict=True)):
            _assert_same(a, b, f"{phase} move {i}")
    for game in games:
        game.close()
