"""Batched evaluation against the per-episode path, measured side by side in one run.

A payoff table of 4 SB3 PPO protagonists × 6 adversary columns × 3 seeds on Hopper-v5, one
worker (``evaluate(jobs, workers=1)`` runs `run_job` per job in this process):

* ``today``: the path before this change: `play_job_sequential` per job (one game, `rollout`
  seed by seed, one policy call per agent per move) with SB3's own ``policy._predict`` per
  call (`ActorForward` switched off), as `SB3Policy` acted before.
* ``sequential``: `advgame.evaluation.table.batched.play_job_sequential` per job, with the leaner
  `ActorForward` per call (same actions, bit for bit).
* ``per-job``: `run_job` per job (all episodes of one job in lockstep, one policy call per
  agent per move for them: the first pass of batching).
* ``batched``: ``evaluate(jobs, workers=1)`` (the jobs grouped by up to `LOCKSTEP_EPISODES`
  episodes and each group played together across jobs, `play_jobs`: a protagonist's network
  is asked once per move for all its columns and seeds, a learned adversary's for all rows;
  each column's games step on one `ArrayGame` while all their episodes are live,
  `advgame.core.array_rollout`).
* ``lockstep``: ``batched`` with the array path off (``array_rollout.USE_ARRAYS = False``):
  every move through the lockstep core.

Protagonists and the learned adversaries are PPO networks ([64, 64]) briefly trained here
(``--train`` steps each; deterministic actions), so episodes last long enough for the per-step
cost to matter; columns: nominal, ``state-gauss-0.1``, ``action-gauss-0.1``, ``shift-uniform``
and two learned PPO adversaries (observation, preset ``default``; force, preset ``rarl``).
* ``simulator``: not a path but the floor under all of them: a raw ``gymnasium.make`` Hopper
  stepped (zero torques, reset when an episode ends) as many times as the table has
  protagonist steps; ``today`` / ``simulator`` bounds what any evaluation path can gain.

The paths run in ``--rounds`` interleaved rounds; reported are the median episodes per
second of each and the median per-round ratio, and the rows of all are checked equal.
``--profile FILE`` writes a cProfile of one more ``batched`` run.
Run: ``python benchmarks/bench_eval_batch.py`` (``--rounds``, ``--episodes``, ``--seeds``,
``--train``).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.core import array_rollout
from advgame.core.views import view_factory
from advgame.evaluation import AdversarySetup, evaluate, population_jobs, run_job
from advgame.evaluation.table.batched import play_job_sequential

ENV = "Hopper-v5"
GOAL = 4.0


def _still(obs: Any) -> np.ndarray:
    """The protagonist the learned adversaries train against: zero torques."""
    return np.zeros(3, dtype=np.float32)


def _ppo(env_fn: Any, steps: int, seed: int, path: Path) -> SB3Checkpoint:
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", env_fn(), n_steps=512, batch_size=64, seed=seed, device="cpu")
    if steps:
        model.learn(steps)
    model.save(path)
    return SB3Checkpoint(str(path), "ppo")


def _today(job: Any) -> list[dict[str, Any]]:
    """`play_job_sequential` with SB3's own predict per call (the policy path before batching)."""
    from advgame.agents import forward

    of = forward.ActorForward.of
    forward.ActorForward.of = staticmethod(lambda policy: None)  # type: ignore[method-assign]
    try:
        return play_job_sequential(job)
    finally:
        forward.ActorForward.of = of  # type: ignore[method-assign]


def _lockstep(jobs: list[Any]) -> list[dict[str, Any]]:
    """``evaluate(jobs, workers=1)`` with the array path off: every move in lockstep."""
    array_rollout.USE_ARRAYS = False
    try:
        return evaluate(jobs, workers=1, progress=False).rows
    finally:
        array_rollout.USE_ARRAYS = True


def _simulator(steps: int) -> None:
    """Step a raw Hopper `steps` times (the simulator's share of a table of that many steps)."""
    import gymnasium as gym

    env = gym.make(ENV)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    env.close()


def table(folder: Path, steps: int, episodes: int, seeds: int = 3) -> list[Any]:
    """The jobs of the 4 × 6 × 3 table (policies trained and saved under `folder`)."""
    protagonists = {
        f"ppo{k}": _ppo(view_factory(ENV, "protagonist"), steps, k, folder / f"p{k}.zip")
        for k in range(4)
    }
    zero = {"protagonist": _still}
    learned_obs = _ppo(
        view_factory(ENV, "observation_adversary", zero, preset="default"),
        steps,
        10,
        folder / "obs_adv.zip",
    )
    learned_force = _ppo(
        view_factory(ENV, "force_adversary", zero, preset="rarl"), steps, 11, folder / "force.zip"
    )
    setups = {
        "nominal": AdversarySetup.nominal(),
        "state-gauss-0.1": AdversarySetup.from_preset(ENV, "state-gauss-0.1"),
        "action-gauss-0.1": AdversarySetup.from_preset(ENV, "action-gauss-0.1"),
        "shift-uniform": AdversarySetup.from_preset(ENV, "shift-uniform"),
        "learned-obs": AdversarySetup(
            {"preset": "default"}, {"observation_adversary": learned_obs}
        ),
        "learned-force": AdversarySetup({"preset": "rarl"}, {"force_adversary": learned_force}),
    }
    return population_jobs(ENV, protagonists, setups, seeds=tuple(range(seeds)), episodes=episodes)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=1, help="episodes per seed")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per job")
    parser.add_argument("--train", type=int, default=4096, help="PPO steps per policy")
    parser.add_argument("--profile", default="", help="write a cProfile of a batched run here")
    args = parser.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        jobs = table(Path(tmp), args.train, args.episodes, args.seeds)
        n = sum(len(j.seeds) * j.episodes for j in jobs)
        paths = {
            "today": lambda: [row for job in jobs for row in _today(job)],
            "sequential": lambda: [row for job in jobs for row in play_job_sequential(job)],
            "per-job": lambda: [row for job in jobs for row in run_job(job)],
            "batched": lambda: evaluate(jobs, workers=1, progress=False).rows,
            "lockstep": lambda: _lockstep(jobs),
        }
        rows: dict[str, list[Any]] = {"today": paths["today"]()}
        steps = sum(int(row["length"]) for row in rows["today"])
        paths["simulator"] = lambda: _simulator(steps) or rows["today"]
        seconds: dict[str, list[float]] = {k: [] for k in paths}
        for r in range(args.rounds):
            for key, play in paths.items():
                start = time.perf_counter()
                rows[key] = play()
                seconds[key].append(time.perf_counter() - start)
            print(f"round {r + 1}/{args.rounds}", flush=True)
        if args.profile:
            import cProfile

            cProfile.runctx("paths['batched']()", globals(), {"paths": paths}, args.profile)
    same = all(rows[k] == rows["today"] for k in paths)
    t = {k: np.asarray(v) for k, v in seconds.items()}
    print(f"\n{ENV}: {len(jobs)} jobs, {n} episodes ({steps} protagonist steps), one worker")
    for key in paths:
        print(f"  {key:10s}: median {np.median(n / t[key]):7.2f} episodes/s")
    for key in ("today", "sequential", "per-job", "lockstep"):
        ratio = np.median(t[key] / t["batched"])
        goal = f" (goal >= {GOAL})" if key == "today" else ""
        print(f"  ratio batched / {key}: median {ratio:.2f}{goal}")
    bound = np.median(t["today"] / t["simulator"])
    print(f"  bound today / simulator alone: median {bound:.2f} (no path can beat it)")
    share = np.median(t["simulator"] / t["batched"])
    print(f"  simulator's share of the batched time: median {share:.2f}")
    print(f"  rows identical: {same}")


if __name__ == "__main__":
    main()
