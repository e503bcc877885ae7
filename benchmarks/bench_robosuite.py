"""Steps/s of every robosuite scenario: the raw robosuite env vs the same task through the game.

Three variants per scenario, in interleaved rounds so that machine noise hits them alike:

* ``raw``: ``robosuite.make(...)`` as advgame builds it (no renderer, no cameras,
  ``hard_reset=False``) with robosuite's own robot class (the games' robots keep their action
  size, `advgame.scenarios.robosuite_lean`), stepped with random actions drawn before timing;
* ``game``: the scenario's game with no disruptor, `Game.play` with the same actions (what the
  game adds: flattening the observation dict, validation, true reward/payoff, truncation);
* ``game+adv``: the ``default`` preset (bounded observation and action adversaries, or the
  adversary arm on MultiRobustDoor) with random adversary actions: two moves per step.

Episodes are 200 steps (reset inside the timing for all three). Reported: the raw env's
median steps/s, and the median (quartiles) over rounds of each variant's ratio to raw in the
same round — robust to the machine's drift. Run: ``python benchmarks/bench_robosuite.py`` (``--steps``,
``--rounds``, ``--only``).
"""

from __future__ import annotations

import argparse
import functools
import time
from typing import Any

import numpy as np
from _common import ratio_table, raw_vs_game

import advgame

HORIZON = 200


def _raw(sid: str) -> tuple[Any, int]:
    from robosuite.robots.fixed_base_robot import FixedBaseRobot

    from advgame.scenarios.robosuite_lean import LeanFixedBaseRobot

    game = advgame.make(sid, disruptors=[])
    env = game.task.env  # the very robosuite env advgame built, used raw
    for robot in env.robots:
        if type(robot) is LeanFixedBaseRobot:
            robot.__class__ = FixedBaseRobot  # robosuite's own step
    return env, env.action_dim


def _time_raw(env: Any, actions: np.ndarray) -> float:
    start, t = time.perf_counter(), 0
    for a in actions:
        env.step(a)
        t += 1
        if t == HORIZON:
            env.reset()
            t = 0
    return time.perf_counter() - start


def bench(sid: str, steps: int, rounds: int, seed: int) -> dict[str, list[float]]:
    """Steps/s of each variant of `sid` in `rounds` interleaved rounds of `steps` steps."""
    rng = np.random.default_rng(seed)
    env, dim = _raw(sid)
    env.reset()
    plain = advgame.make(sid, disruptors=[], max_episode_steps=HORIZON)
    attacked = advgame.make(sid, preset="default", max_episode_steps=HORIZON)
    for g in (plain, attacked):
        g.reset(seed=seed)
    draw = functools.partial(rng.uniform, -1, 1, (steps, dim))
    return raw_vs_game(functools.partial(_time_raw, env), plain, attacked, draw, rounds, rng)


def main() -> None:
    """Benchmark every robosuite scenario (or ``--only``) and print a Markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--only", nargs="*", default=None)
    args = parser.parse_args()
    ids = args.only or advgame.list_scenarios("robosuite")
    warm = advgame.make(ids[0], disruptors=[])
    warm.reset(seed=0)
    warm.play({"protagonist": warm.action_space("protagonist").sample()})  # numba compiles here
    ratio_table("scenario", ids, bench, args.steps, args.rounds)


if __name__ == "__main__":
    main()
