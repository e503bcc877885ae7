"""Steps/s of every robosuite scenario: the raw robosuite env vs the same task through the game.

Three variants per scenario, in interleaved rounds so that machine noise hits them alike:

* ``raw``: ``robosuite.make(...)`` as advgame builds it (no renderer, no cameras,
  ``hard_reset=False``), stepped with random actions drawn before timing;
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
import time
from typing import Any

import numpy as np
from _common import ratio_row

import advgame

HORIZON = 200


def _raw(sid: str) -> tuple[Any, int]:
    game = advgame.make(sid, disruptors=[])
    env = game.task.env  # the very robosuite env advgame built, used raw
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


def _time_game(game: advgame.Game, actions: np.ndarray, rng: np.random.Generator) -> float:
    adv = {
        a: rng.uniform(-1, 1, (len(actions), *game.action_space(a).shape)) for a in game.adversaries
    }
    size = game.action_space("protagonist").shape[0]
    start, i = time.perf_counter(), 0
    while i < len(actions):
        if not game.agents:
            game.reset()
        move = {a: adv[a][i].astype(np.float32) for a in game.next_movers if a in adv}
        if "protagonist" in game.next_movers:
            move["protagonist"] = actions[i][:size]
            i += 1
        game.play(move)
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
    out: dict[str, list[float]] = {"raw": [], "game": [], "game+adv": []}
    for _ in range(rounds):
        actions = rng.uniform(-1, 1, (steps, dim))
        out["raw"].append(steps / _time_raw(env, actions))
        out["game"].append(steps / _time_game(plain, actions, rng))
        out["game+adv"].append(steps / _time_game(attacked, actions, rng))
    return out


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
    lines = [
        f"{args.rounds} interleaved rounds of {args.steps} steps; raw: median steps/s; "
        "game, game+adv: median per-round ratio to raw (quartiles)",
        "| scenario | raw steps/s | game / raw | game+adv / raw |",
        "|---|---|---|---|",
    ]
    for sid in ids:
        r = bench(sid, args.steps, args.rounds, 0)
        lines.append(ratio_row(sid, r))
        print(lines[-1], flush=True)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
