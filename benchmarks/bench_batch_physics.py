"""Batched MuJoCo physics beside SyncVectorEnv, EnvPool and raw ``mujoco.rollout``, in one run.

Ways of stepping N copies of a MuJoCo v5 task (``--env``, default HalfCheetah-v5) with uniformly
random actions (drawn before timing), for N in ``--n`` (default 8, 16, 64):

* ``sync``: Gymnasium's ``SyncVectorEnv`` of N ``gymnasium.make(env)`` (the reference: 1.00).
* ``batch-tK``: `advgame.scenarios.mujoco_batch.BatchedMujocoEnv` with K simulator threads:
  the same envs bit for bit, observations/rewards/infos computed over ``[N, ...]``.
* ``stepper-tK``: the batched env's physics alone (`advgame.core.physics.ThreadedStepper`:
  controls set, ``mj_step`` on K threads; no observations, rewards or infos), so that
  ``batch-tK`` minus it is the NumPy side's cost. Each thread's share is one compiled call
  (`advgame.core.native_step`) where numba is installed.
* ``bindings-tK``: the same stepper with ``native=False``: a Python loop of MuJoCo's bindings,
  one call (and one GIL hand-off) per env; ``stepper-tK / bindings-tK`` is the compiled loop's
  gain (its per-round ratio is printed).
* ``game-tK``: `advgame.core.vector.VectorView` of N protagonist views of preset ``default``
  with `RandomAdversary` observation and action adversaries (three agents, two moves per
  step, budgets checked), K simulator threads (``ADVGAME_PHYSICS_THREADS``): the batched game.
* ``envpool-tK``: EnvPool's own ``<env>`` with K threads (``pip install envpool``; skipped when
  absent). A reference only: its own MuJoCo build, no adversaries, no model edits.
* ``rollout-tK``: ``mujoco.rollout`` of the N states, one call per move with ``frame_skip``
  substeps and K threads, physics only (no observations or rewards, the solver's warmstart
  lost between moves): what MuJoCo's one-call batched path costs, the ceiling of that design.

Each variant is built once and stepped in segments of ``--chunk`` vector steps, the variants
interleaved for ``--rounds`` rounds; each segment is compared with the ``sync`` segment of the
same round (the speed of a shared machine drifts within seconds). Reported: median env-steps/s
of ``sync`` and the quartiles of every variant's per-round ratio to it.
Run: ``python benchmarks/bench_batch_physics.py`` (``--env``, ``--n``, ``--threads``,
``--rounds``, ``--chunk``). Needs quiet cores: never run it beside training.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from _common import quartiles

from advgame.core.physics import THREADS_VAR, ThreadedStepper
from advgame.scenarios.mujoco_batch import BatchedMujocoEnv


class _Rollout:
    """The physics-only reference: N states advanced by one ``mujoco.rollout`` call per move."""

    def __init__(self, env_id: str, n: int, threads: int) -> None:
        import mujoco
        from mujoco import rollout

        env = gym.make(env_id).unwrapped
        env.reset(seed=0)
        self.model, self.frame_skip = env.model, env.frame_skip
        self.runner = rollout.Rollout(nthread=threads if threads > 1 else 0)
        self.datas = [mujoco.MjData(self.model) for _ in range(max(1, threads))]
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        size = mujoco.mj_stateSize(self.model, spec)
        state = np.zeros(size)
        mujoco.mj_getState(self.model, env.data, state, spec)
        self.state0 = np.tile(state, (n, 1))
        self.states = np.zeros((n, self.frame_skip, size))
        self.models = [self.model] * n

    def step(self, actions: np.ndarray) -> None:
        control = np.repeat(actions[:, None, :], self.frame_skip, axis=1)
        self.runner.rollout(
            self.models,
            self.datas,
            self.state0,
            control,
            skip_checks=True,
            nstep=self.frame_skip,
            state=self.states,
        )
        self.state0 = np.ascontiguousarray(self.states[:, -1])

    def close(self) -> None:
        self.runner.close()


class _Stepper:
    """The exact physics alone: `ThreadedStepper` over N unwrapped envs, nothing computed after."""

    def __init__(self, env_id: str, n: int, threads: int, native: bool = True) -> None:
        self.envs = [gym.make(env_id).unwrapped for _ in range(n)]
        for i, env in enumerate(self.envs):
            env.reset(seed=i)
        self.stepper = ThreadedStepper(threads, native=native)
        self.frame_skip = self.envs[0].frame_skip

    def step(self, actions: np.ndarray) -> None:
        self.stepper.step(self.envs, actions, self.frame_skip, post_constraint=False)

    def close(self) -> None:
        self.stepper.close()


class GameViews:
    """The batched game: a `VectorView` of protagonist views with random adversaries.

    ``array=False`` keeps `VectorView`'s lockstep path (`benchmarks/bench_array_game.py`).
    """

    def __init__(self, env_id: str, n: int, threads: int, array: bool = True) -> None:
        from advgame.adversaries import RandomAdversary
        from advgame.core.vector import VectorView
        from advgame.core.views import view_factory

        policies = {a: RandomAdversary() for a in ("observation_adversary", "action_adversary")}
        self.threads = str(threads)
        self.venv = VectorView(
            [view_factory(env_id, "protagonist", policies, preset="default")] * n, array=array
        )
        self.venv.seed(0)

    def reset(self, seed: int) -> None:
        """Reset every view (their seeds were set at construction)."""
        self.venv.reset()

    def step(self, actions: np.ndarray) -> None:
        """One vector step, on this variant's simulator threads."""
        os.environ[THREADS_VAR] = self.threads
        self.venv.step(actions)

    def close(self) -> None:
        """Close the views' games."""
        self.venv.close()


def _variants(env_id: str, n: int, threads: list[int]) -> dict[str, Callable[[], Any]]:
    out: dict[str, Callable[[], Any]] = {
        "sync": lambda: gym.vector.SyncVectorEnv([lambda: gym.make(env_id)] * n)
    }
    for k in threads:
        out[f"batch-t{k}"] = lambda k=k: BatchedMujocoEnv(env_id, n, threads=k)
    for k in threads:
        out[f"stepper-t{k}"] = lambda k=k: _Stepper(env_id, n, k)
        out[f"bindings-t{k}"] = lambda k=k: _Stepper(env_id, n, k, native=False)
    for k in threads:
        out[f"game-t{k}"] = lambda k=k: GameViews(env_id, n, k)
    try:
        import envpool

        for k in threads:
            out[f"envpool-t{k}"] = lambda k=k: envpool.make_gymnasium(
                env_id, num_envs=n, num_threads=k, seed=0
            )
    except ImportError:
        print("envpool is not installed: its columns are skipped (pip install envpool)")
    for k in threads:
        out[f"rollout-t{k}"] = lambda k=k: _Rollout(env_id, n, k)
    return out


def measure(env_id: str, n: int, threads: list[int], rounds: int, chunk: int) -> dict:
    """Env-steps/s of every variant per round, interleaved."""
    low, high = gym.make(env_id).action_space.low, gym.make(env_id).action_space.high
    actions = np.random.default_rng(0).uniform(low, high, (chunk, n, len(low)))
    envs = {name: make() for name, make in _variants(env_id, n, threads).items()}
    for name, env in envs.items():
        if name.startswith("envpool"):
            env.reset()  # seeded at construction
        elif hasattr(env, "reset"):
            env.reset(seed=0)
    rates: dict[str, list[float]] = {name: [] for name in envs}
    for _ in range(rounds):
        for name, env in envs.items():
            acts = actions.astype(np.float64 if name.startswith("envpool") else np.float32)
            start = time.perf_counter()
            for a in acts:
                env.step(a)
            rates[name].append(chunk * n / (time.perf_counter() - start))
    for env in envs.values():
        env.close()
    return rates


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="HalfCheetah-v5")
    parser.add_argument("--n", default="8,16,64")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--chunk", type=int, default=50, help="vector steps per segment")
    args = parser.parse_args()
    threads = [int(k) for k in args.threads.split(",")]
    header = None
    for n in (int(x) for x in args.n.split(",")):
        rates = measure(args.env, n, threads, args.rounds, args.chunk)
        if header is None:
            others = [k for k in rates if k != "sync"]
            header = f"| {args.env} N | sync steps/s | " + " | ".join(others) + " |"
            print(header)
            print("|" + "---|" * (2 + len(others)))
        cells = [
            quartiles([v / s for v, s in zip(values, rates["sync"], strict=True)])
            for key, values in rates.items()
            if key != "sync"
        ]
        print(f"| {n} | {statistics.median(rates['sync']):.0f} | " + " | ".join(cells) + " |")
        for k in threads:  # the compiled loop against the bindings' loop, round by round
            ratios = [
                a / b for a, b in zip(rates[f"stepper-t{k}"], rates[f"bindings-t{k}"], strict=True)
            ]
            print(f"  N={n} stepper-t{k} / bindings-t{k}, per round: {quartiles(ratios)}")


if __name__ == "__main__":
    main()
