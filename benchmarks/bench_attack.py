"""Attacked evaluation against nominal evaluation, side by side in one run (issue 21, part 7).

One PPO protagonist on InvertedPendulum-v5, trained here for ``--train`` steps with plain SB3
(deterministic actions, no normalizer), is played for ``--episodes`` episodes (seeds 0..E-1),
one worker, in ``--rounds`` interleaved rounds:

* ``nominal``: the undisrupted game, `evaluate` of one job of E seeds (lockstep episodes);
* ``mad alone``: `MADAttack()` (10 steps) in preset ``default``, each seed its own job played
  by `run_job` (one game at a time: the path attacks took before batching);
* ``mad batched``: the same attack, one job of E seeds through `evaluate` (the games of the
  lockstep group attacked in one walk over ``[E, k]``).

Reported: the median protagonist steps per second of each, and the ratios attacked /
nominal (the goal: batched ≥ 0.25). The rows of the two attacked paths are checked equal.
Run: ``python benchmarks/bench_attack.py [--rounds 3] [--episodes 16] [--train 20000]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from advgame.adversaries import MADAttack
from advgame.evaluation import (
    AdversarySetup,
    evaluate,
    population_jobs,
    run_job,
    sb3_protagonist,
    split_seeds,
)

ENV = "InvertedPendulum-v5"
GOAL = 0.25


def _train(steps: int, folder: Path) -> Any:
    import gymnasium as gym
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", gym.make(ENV), n_steps=1024, batch_size=64, seed=0, device="cpu")
    model.learn(steps)
    model.save(folder / "ppo.zip")
    return sb3_protagonist(folder / "ppo.zip", raw_observations=True)


def _timed(fn: Any) -> tuple[float, list[dict[str, Any]]]:
    start = time.perf_counter()
    rows = fn()
    return time.perf_counter() - start, rows


def main() -> None:
    """Train the protagonist, time the three paths in interleaved rounds, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument("--train", type=int, default=20_000)
    args = parser.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        prot = {"ppo": _train(args.train, Path(tmp))}
        seeds = tuple(range(args.episodes))
        nominal = population_jobs(ENV, prot, {"nominal": AdversarySetup.nominal()}, seeds=seeds)
        mad = AdversarySetup({"preset": "default"}, {"observation_adversary": MADAttack()})
        attacked = population_jobs(ENV, prot, {"mad": mad}, seeds=seeds)
        paths = {
            "nominal": lambda: evaluate(nominal, progress=False).rows,
            "mad alone": lambda: [r for u in split_seeds(attacked, 1) for r in run_job(u)],
            "mad batched": lambda: evaluate(attacked, progress=False).rows,
        }
        rates: dict[str, list[float]] = {k: [] for k in paths}
        for _ in range(args.rounds):
            rows = {}
            for name, fn in paths.items():
                seconds, rows[name] = _timed(fn)
                rates[name].append(sum(r["length"] for r in rows[name]) / seconds)
            key = ("seed", "true_return", "length")
            assert sorted(tuple(r[k] for k in key) for r in rows["mad alone"]) == sorted(
                tuple(r[k] for k in key) for r in rows["mad batched"]
            ), "batched attack rows differ from the lone games'"
    nom = float(np.median(rates["nominal"]))
    print(f"{ENV}, {args.episodes} episodes, {args.rounds} rounds, one worker")
    print(f"{'path':<12} {'steps/s':>9} {'/ nominal':>10}")
    for name, values in rates.items():
        med = float(np.median(values))
        print(f"{name:<12} {med:>9.0f} {med / nom:>10.3f}")
    ok = np.median(rates["mad batched"]) / nom >= GOAL
    print(f"goal batched / nominal >= {GOAL}: {'met' if ok else 'not met'}")


if __name__ == "__main__":
    main()
