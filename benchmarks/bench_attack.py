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

Then a recurrent victim (issue 40): an untrained sb3-contrib ``RecurrentPPO`` on Hopper-v5 (one
64-unit LSTM read out linearly, ``net_arch=[]``, ATLA's LSTM policy), ``--lstm-episodes``
episodes through `evaluate`, in the same interleaved rounds:

* ``lstm nominal``: the undisrupted game;
* ``lstm mad``: `MADAttack()` in preset ``default``; each game walks alone (a recurrent
  victim carries its own memory: no batched walk), through the NumPy LSTM step at the carried
  memory (`advgame.core.numpy_lstm`); ``lstm mad torch`` walks through torch instead.

Reported likewise, with the ratio ``lstm mad`` / ``lstm nominal`` against the same goal.
Run: ``python benchmarks/bench_attack.py [--rounds 3] [--episodes 16] [--train 20000]
[--lstm-episodes 8] [--victims ppo lstm]``; ``--smoke`` runs every path once, tiny, to check
the script (its numbers mean nothing). Needs quiet cores: never time it beside training.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from calibrate import line, step_us

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
LSTM_ENV = "Hopper-v5"
GOAL = 0.25


def _train(steps: int, folder: Path) -> Any:
    import gymnasium as gym
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", gym.make(ENV), n_steps=1024, batch_size=64, seed=0, device="cpu")
    model.learn(steps)
    model.save(folder / "ppo.zip")
    return sb3_protagonist(folder / "ppo.zip", raw_observations=True)


def _lstm(folder: Path) -> Any:
    """An untrained RecurrentPPO on Hopper-v5 (64 LSTM units, linear read-out), saved."""
    import gymnasium as gym
    from sb3_contrib import RecurrentPPO

    kwargs = {"lstm_hidden_size": 64, "net_arch": []}
    model = RecurrentPPO(
        "MlpLstmPolicy", gym.make(LSTM_ENV), policy_kwargs=kwargs, seed=0, device="cpu"
    )
    model.save(folder / "lstm.zip")
    return sb3_protagonist(folder / "lstm.zip", "recurrent-ppo", raw_observations=True)


def _timed(fn: Any) -> tuple[float, list[dict[str, Any]]]:
    start = time.perf_counter()
    rows = fn()
    return time.perf_counter() - start, rows


def _rates(paths: dict[str, Any], rounds: int) -> tuple[dict[str, list[float]], dict[str, Any]]:
    """Steps per second of every path in each of `rounds` interleaved rounds; the last rows."""
    rates: dict[str, list[float]] = {k: [] for k in paths}
    rows: dict[str, Any] = {}
    for _ in range(rounds):
        rows = {}
        for name, fn in paths.items():
            seconds, rows[name] = _timed(fn)
            rates[name].append(sum(r["length"] for r in rows[name]) / seconds)
    return rates, rows


def _jobs(env: str, prot: dict[str, Any], episodes: int) -> tuple[Any, Any]:
    """The nominal and the MAD-attacked (preset ``default``) jobs of `prot`, one per episode."""
    seeds = tuple(range(episodes))
    nominal = population_jobs(env, prot, {"nominal": AdversarySetup.nominal()}, seeds=seeds)
    mad = AdversarySetup({"preset": "default"}, {"observation_adversary": MADAttack()})
    return nominal, population_jobs(env, prot, {"mad": mad}, seeds=seeds)


def ppo_rates(folder: Path, episodes: int, rounds: int, train: int) -> dict[str, list[float]]:
    """The PPO protagonist's three paths (the rows of the two attacked ones checked equal)."""
    nominal, attacked = _jobs(ENV, {"ppo": _train(train, folder)}, episodes)
    paths = {
        "nominal": lambda: evaluate(nominal, progress=False).rows,
        "mad alone": lambda: [r for u in split_seeds(attacked, 1) for r in run_job(u)],
        "mad batched": lambda: evaluate(attacked, progress=False).rows,
    }
    rates, rows = _rates(paths, rounds)
    key = ("seed", "true_return", "length")
    assert sorted(tuple(r[k] for k in key) for r in rows["mad alone"]) == sorted(
        tuple(r[k] for k in key) for r in rows["mad batched"]
    ), "batched attack rows differ from the lone games'"
    return rates


def lstm_rates(folder: Path, episodes: int, rounds: int) -> dict[str, list[float]]:
    """The recurrent victim's two paths: nominal and MAD-attacked, through `evaluate`."""
    nominal, attacked = _jobs(LSTM_ENV, {"lstm": _lstm(folder)}, episodes)
    paths = {
        "lstm nominal": lambda: evaluate(nominal, progress=False).rows,
        "lstm mad": lambda: evaluate(attacked, progress=False).rows,
        "lstm mad torch": lambda: _through_torch(lambda: evaluate(attacked, progress=False).rows),
    }
    return _rates(paths, rounds)[0]


def _through_torch(fn: Any) -> Any:
    """`fn()` with the recurrent victim's NumPy copy withheld: the walk goes through torch."""
    from advgame.agents.common.recurrent_policy import RecurrentSB3Policy

    saved = RecurrentSB3Policy.numpy_net
    RecurrentSB3Policy.numpy_net = lambda self, head: None  # type: ignore[method-assign]
    try:
        return fn()
    finally:
        RecurrentSB3Policy.numpy_net = saved  # type: ignore[method-assign]


def _report(title: str, rates: dict[str, list[float]], attacked: str) -> None:
    """Print one table: each path's median steps/s and its ratio to the first (nominal)."""
    nom = float(np.median(next(iter(rates.values()))))
    print(title)
    print(f"{'path':<15} {'steps/s':>9} {'/ nominal':>10}")
    for name, values in rates.items():
        med = float(np.median(values))
        print(f"{name:<15} {med:>9.0f} {med / nom:>10.3f}")
    ok = np.median(rates[attacked]) / nom >= GOAL
    print(f"goal {attacked} / nominal >= {GOAL}: {'met' if ok else 'not met'}")


def main(argv: list[str] | None = None) -> None:
    """Build the protagonists, time their paths in interleaved rounds, print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument("--train", type=int, default=20_000)
    parser.add_argument("--lstm-episodes", type=int, default=8)
    parser.add_argument("--victims", nargs="+", choices=("ppo", "lstm"), default=["ppo", "lstm"])
    parser.add_argument("--smoke", action="store_true", help="every path once, tiny: a check")
    args = parser.parse_args(argv)
    if args.smoke:
        args.rounds, args.episodes, args.train, args.lstm_episodes = 1, 2, 256, 1
    torch.set_num_threads(1)
    steps = 2_000 if args.smoke else 5_000  # the calibration's raw steps per repeat

    def calibrated() -> str:
        return line(step_us(steps=steps, repeats=3), steps, 3)

    print(f"before: {calibrated()}")
    with tempfile.TemporaryDirectory() as tmp:
        if "ppo" in args.victims:
            rates = ppo_rates(Path(tmp), args.episodes, args.rounds, args.train)
            title = f"{ENV}, {args.episodes} episodes, {args.rounds} rounds, one worker"
            _report(title, rates, "mad batched")
        if "lstm" in args.victims:
            rates = lstm_rates(Path(tmp), args.lstm_episodes, args.rounds)
            title = f"{LSTM_ENV}, RecurrentPPO (64 LSTM units), {args.lstm_episodes} episodes, "
            _report(title + f"{args.rounds} rounds, one worker", rates, "lstm mad")
    print(f"after: {calibrated()}")


if __name__ == "__main__":
    main()
