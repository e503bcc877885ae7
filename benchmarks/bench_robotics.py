"""Steps/s of one gymnasium-robotics task per family: the raw env vs the same task through the game.

Three variants per task, in interleaved rounds so that machine noise hits them alike:

* ``raw``: the Gymnasium env advgame builds (``gymnasium.make(id)``, env checker off), stepped
  with random actions drawn before timing, reset at the end of each episode;
* ``game``: the scenario's game with no disruptor, `Game.play` with the same actions (what the
  game adds: copying the Dict observation, flattening the adversaries' true state, ``is_success``
  and the true goals in the info, validation, truncation);
* ``game+adv``: the ``default`` preset (per-key bounded observation attack on every Dict leaf and
  a bounded action attack) with random adversary actions: two moves per step.

Episodes run to each task's own horizon (reset inside the timing for all three). Reported: the
raw env's median steps/s, and the median (quartiles) over rounds of each variant's ratio to raw
in the same round — robust to the machine's drift. Run: ``python benchmarks/bench_robotics.py``
(``--steps``, ``--rounds``, ``--only``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _common import ratio_row, step_through

import advgame

TASKS = (
    "PointMaze_UMaze-v3",
    "FetchPush-v4",
    "HandManipulateBlock-v1",
    "AdroitHandDoor-v1",
    "FrankaKitchen-v1",
)
"""One task per family: maze, fetch, hand, adroit, kitchen."""


def _time_game(game: advgame.Game, actions: np.ndarray, rng: np.random.Generator) -> float:
    adv = {
        a: rng.uniform(-1, 1, (len(actions), *game.action_space(a).shape)).astype(np.float32)
        for a in game.adversaries
    }
    start, i = time.perf_counter(), 0
    while i < len(actions):
        if not game.agents:
            game.reset()
        move = {a: adv[a][i] for a in game.next_movers if a in adv}
        if "protagonist" in game.next_movers:
            move["protagonist"] = actions[i]
            i += 1
        game.play(move)
    return time.perf_counter() - start


def bench(sid: str, steps: int, rounds: int, seed: int) -> dict[str, list[float]]:
    """Steps/s of each variant of `sid` in `rounds` interleaved rounds of `steps` steps."""
    rng = np.random.default_rng(seed)
    plain = advgame.make(sid, disruptors=[])
    attacked = advgame.make(sid, preset="default")
    raw = advgame.make(sid, disruptors=[]).task.env  # type: ignore[attr-defined]
    raw.reset(seed=seed)
    for g in (plain, attacked):
        g.reset(seed=seed)
    space = plain.action_space("protagonist")
    out: dict[str, list[float]] = {"raw": [], "game": [], "game+adv": []}
    for _ in range(rounds):
        actions = rng.uniform(space.low, space.high, (steps, *space.shape)).astype(space.dtype)
        out["raw"].append(steps / step_through(raw, actions))
        out["game"].append(steps / _time_game(plain, actions, rng))
        out["game+adv"].append(steps / _time_game(attacked, actions, rng))
    return out


def main() -> None:
    """Benchmark one task per robotics family (or ``--only``) and print a Markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--only", nargs="*", default=None)
    args = parser.parse_args()
    lines = [
        f"{args.rounds} interleaved rounds of {args.steps} steps; raw: median steps/s; "
        "game, game+adv: median per-round ratio to raw (quartiles)",
        "| task | raw steps/s | game / raw | game+adv / raw |",
        "|---|---|---|---|",
    ]
    for sid in args.only or TASKS:
        r = bench(sid, args.steps, args.rounds, 0)
        lines.append(ratio_row(sid, r))
        print(lines[-1], flush=True)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
