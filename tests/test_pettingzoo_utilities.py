"""PettingZoo's own test utilities, on one game of every scenario family in the registry.

`tests/test_conformance.py` already runs `parallel_api_test` and `parallel_seed_test` on every
scenario; this file runs the rest of `pettingzoo.test` on one scenario per family (its first
registered id, ``default`` preset), as an outside client sees the game:

* `api_test` on ``parallel_to_aec(game)``: the AEC form that Tianshou and TorchRL's AEC path read;
* `max_cycles_test`: PettingZoo counts *cycles* as ``ParallelEnv.step`` calls, i.e. advgame's
  moves. A protagonist step with a sense move is two moves, so the test module's
  ``parallel_env(max_cycles)`` makes the game with the ``max_episode_steps`` that gives that
  many moves (measured, not assumed), and the test fails, saying so, where none does;
* `render_test`, in a process of its own with headless OpenGL (``MUJOCO_GL=egl``), over the
  render modes the task base lists except ``"human"``, which opens a window (CI has no
  display). Families whose task base lists no render mode (robosuite: a state-only task) cannot
  take it: there the test checks that `Game.render` raises `UnsupportedError` naming the scenario;
* `performance_benchmark`, on ``parallel_to_aec(game)`` with episodes of 3 steps, under a clock
  that advances 50 ms a call: the real loop (turns, episode ends, resets) for 100 cycles
  instead of 5 seconds of wall time a family; the rate it prints is not a measurement.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import types

import pytest
from pettingzoo.test import api_test, max_cycles_test, performance_benchmark
from pettingzoo.utils.conversions import parallel_to_aec

import advgame
from advgame.core.registry import scenario_spec
from advgame.errors import UnsupportedError
from tests.test_conformance import _needs_extra


def _representatives() -> dict[str, str]:
    """Family -> its first registered scenario id (a new family is covered without an edit)."""
    out: dict[str, str] = {}
    for sid in advgame.list_scenarios():
        out.setdefault(scenario_spec(sid).family, sid)
    return out


FAMILIES = _representatives()
CASES = [pytest.param(sid, id=f"{family}:{sid}", marks=_needs_extra(sid)) for family, sid in FAMILIES.items()]  # fmt: skip


def _preset(sid: str) -> str:
    presets = scenario_spec(sid).load_presets()
    return "default" if "default" in presets else next(iter(presets))


def _moves(sid: str, steps: int) -> int:
    """Moves (``step`` calls) in one seeded episode of `steps` protagonist steps."""
    game = advgame.make(sid, preset=_preset(sid), max_episode_steps=steps)
    game.reset(seed=0)
    for i, agent in enumerate(game.possible_agents):
        game.action_space(agent).seed(i)
    moves = 0
    while game.agents:
        game.step({a: game.action_space(a).sample() for a in game.agents})
        moves += 1
    game.close()
    return moves


def _steps_for(sid: str, cycles: int) -> int:
    """The ``max_episode_steps`` whose episode is `cycles` moves long."""
    one, two = _moves(sid, 1), _moves(sid, 2)
    per_step, setup = two - one, 2 * one - two
    steps, rest = divmod(cycles - setup, per_step)
    if rest or steps < 1:
        pytest.fail(
            f"{sid}: an episode is {setup} + {per_step}·steps moves, so no max_episode_steps "
            f"gives max_cycles_test's {cycles} cycles; PettingZoo's max_cycles cannot apply."
        )
    return steps


def _cycles_module(sid: str) -> types.SimpleNamespace:
    """The ``mod`` `max_cycles_test` takes: ``parallel_env`` and ``env`` with ``max_cycles``."""

    def parallel_env(max_cycles: int) -> advgame.Game:
        steps = _steps_for(sid, max_cycles)
        return advgame.make(sid, preset=_preset(sid), max_episode_steps=steps)

    return types.SimpleNamespace(
        parallel_env=parallel_env, env=lambda max_cycles: parallel_to_aec(parallel_env(max_cycles))
    )


@pytest.mark.parametrize("sid", CASES)
def test_api_test_on_the_aec_form(sid: str) -> None:
    game = advgame.make(sid, preset=_preset(sid), max_episode_steps=10)
    api_test(parallel_to_aec(game), num_cycles=40)
    game.close()


@pytest.mark.parametrize("sid", CASES)
def test_max_cycles_test(sid: str) -> None:
    max_cycles_test(_cycles_module(sid))


class _FastClock:
    """Stands in for `time` in `performance_benchmark`: 50 ms pass at every call."""

    def __init__(self) -> None:
        self.now = 0.0

    def time(self) -> float:
        self.now += 0.05
        return self.now


@pytest.mark.parametrize("sid", CASES)
def test_performance_benchmark(
    sid: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # the package re-exports the function under the module's name: fetch the module itself
    module = importlib.import_module("pettingzoo.test.performance_benchmark")
    monkeypatch.setattr(module, "time", _FastClock())
    game = advgame.make(sid, preset=_preset(sid), max_episode_steps=3)
    performance_benchmark(parallel_to_aec(game))
    game.close()
    assert "Finished performance benchmark" in capsys.readouterr().out


RENDER = """
import json, sys
import advgame
from pettingzoo.test import render_test
from pettingzoo.utils.conversions import parallel_to_aec
sid, preset, modes = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
def env_fn(render_mode=None):
    game = advgame.make(sid, preset=preset, render_mode=render_mode, max_episode_steps=20)
    game.metadata = {**game.metadata, "render_modes": modes}  # "human" left out: no display
    return parallel_to_aec(game)  # render_test plays the AEC form
render_test(env_fn)
"""


def _run(code: str, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "MUJOCO_GL": "egl", "SDL_VIDEODRIVER": "dummy"}
    return subprocess.run(
        [sys.executable, "-c", code, *args], env=env, capture_output=True, text=True, timeout=300
    )


@pytest.mark.parametrize("sid", CASES)
def test_render_test(sid: str) -> None:
    game = advgame.make(sid, preset=_preset(sid))
    modes: list[str] = [m for m in game.metadata["render_modes"] if m != "human"]
    if not modes:  # a state-only task base: render_test cannot apply; the game says why
        with pytest.raises(UnsupportedError, match=sid):
            game.render()
        with pytest.raises(UnsupportedError, match="no render modes"):
            advgame.make(sid, preset=_preset(sid), render_mode="rgb_array")
        game.close()
        return
    game.close()
    proc = _run(RENDER, sid, _preset(sid), json.dumps(modes))
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_every_family_has_a_case() -> None:
    assert set(FAMILIES) == {scenario_spec(s).family for s in advgame.list_scenarios()}
    assert {"mujoco", "box2d", "safe", "mamujoco", "robosuite"} <= set(FAMILIES)


def test_render_without_a_mode_names_the_scenario() -> None:
    game = advgame.make("HalfCheetah-v5", preset="default")
    with pytest.raises(UnsupportedError, match=r"HalfCheetah-v5 cannot render.*render_mode="):
        game.render()
    assert game.render_mode is None and "rgb_array" in game.metadata["render_modes"]
    assert game.unwrapped is game
    game.close()
