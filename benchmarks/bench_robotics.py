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
import functools

import numpy as np
from _common import ratio_table, raw_vs_game, step_through

import advgame

TASKS = (
    "PointMaze_UMaze-v3",
    "FetchPush-v4",
    "HandManipulateBlock-v1",
    "AdroitHandDoor-v1",
    "FrankaKitchen-v1",
)
"""One task per family: maze, fetch, hand, adroit, kitchen."""


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

    def draw() -> np.ndarray:
        return rng.uniform(space.low, space.high, (steps, *space.shape)).astype(space.dtype)

    return raw_vs_game(functools.partial(step_through, raw), plain, attacked, draw, rounds, rng)


def main() -> None:
    """Benchmark one task per robotics family (or ``--only``) and print a Markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--only", nargs="*", default=None)
    args = parser.parse_args()
    ratio_table("task", args.only or TASKS, bench, args.steps, args.rounds)


if __name__ == "__main__":
    main()
