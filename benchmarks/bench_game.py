"""Overhead of the game layers over the raw Gymnasium env, measured side by side in one run.

Four ways of stepping HalfCheetah-v5 with uniformly random actions (drawn before timing):

* ``raw``: ``gymnasium.make("HalfCheetah-v5")`` (its default wrappers), ``env.step``.
* ``wrapper``: a reference point, not part of advgame: the same env under a plain
  ``gymnasium.ObservationWrapper`` that adds ``N(0, 0.1)`` noise (no adversary agent, no checks,
  no payoff bookkeeping) — the cheapest conventional way to add the same noise.
* ``view``: the protagonist's `SingleAgentView` of preset ``state-gauss-0.1`` with an embedded
  `GaussianAdversary` (σ = 0.1) on the observation: a sense move and an act move per step.
* ``parallel``: the full PettingZoo `Game.step` of preset ``default`` (bounded observation and
  action adversaries), random actions for all three agents, two moves per step.

And, vectorised (``--n`` envs, default 8), per env step:

* ``sync``: Gymnasium's ``SyncVectorEnv`` of ``n`` raw ``gymnasium.make("HalfCheetah-v5")``.
* ``dummy``: a reference point, not part of advgame: SB3's ``DummyVecEnv`` of ``n`` raw envs
  under the plain noise wrapper above (the cheapest conventional SB3 `VecEnv` with the noise).
* ``vector``: `advgame.core.vector.VectorView` of ``n`` protagonist views as ``view`` above
  (an SB3 `VecEnv`; autoreset as `DummyVecEnv`).

Each env is built once and stepped in many short segments (``--chunk`` env steps), interleaved
raw, wrapper, view, parallel, sync, dummy, vector, raw, ... for ``--rounds`` rounds; episodes run on
across segments. The vectorised rows are compared with ``sync`` (``dummy`` / ``sync``, ``vector`` / ``sync``).
On a shared or virtualised machine the speed of the whole machine drifts by tens of percent
within seconds, so each segment is compared with the raw segment just before it: reported are
the quartiles of those per-round ratios and the median extra time per step in µs.
Run: ``python benchmarks/bench_game.py`` (``--rounds``, ``--chunk``).
"""

from __future__ import annotations

import argparse
import functools
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from _common import step_through

import advgame
from advgame.adversaries import GaussianAdversary
from advgame.core.views import SingleAgentView

ENV = "HalfCheetah-v5"
GOALS = {"view": 0.90, "parallel": 0.80, "vector": 0.95}


class _NoiseWrapper(gym.ObservationWrapper):
    """The reference: N(0, 0.1) added to every observation by a plain Gymnasium wrapper."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.rng = np.random.default_rng(0)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return observation + self.rng.normal(0.0, 0.1, observation.shape)


def _gym_runner(env: gym.Env) -> Callable[[np.ndarray], float]:
    env.reset(seed=0)
    return functools.partial(step_through, env)


def _parallel_runner(adv_obs: np.ndarray, adv_act: np.ndarray) -> Callable[[np.ndarray], float]:
    game = advgame.make(ENV, preset="default")
    game.reset(seed=0)

    def run(actions: np.ndarray) -> float:
        steps = 0
        start = time.perf_counter()
        while steps < len(actions):
            move = {
                "protagonist": actions[steps],
                "observation_adversary": adv_obs[steps],
                "action_adversary": adv_act[steps],
            }
            if game.move == "act":
                steps += 1
            game.step(move)
            if not game.agents:
                game.reset()
        return time.perf_counter() - start

    return run


def _vector_runners(n: int) -> dict[str, Callable[[np.ndarray], float]]:
    """``sync``, ``dummy`` and ``vector``: each steps `n` envs with ``actions[k : k + n]`` per step."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from advgame.core.vector import VectorView
    from advgame.core.views import view_factory

    sync = gym.vector.SyncVectorEnv([functools.partial(gym.make, ENV) for _ in range(n)])
    sync.reset(seed=0)
    dummy = DummyVecEnv([lambda: _NoiseWrapper(gym.make(ENV)) for _ in range(n)])
    dummy.seed(0)
    dummy.reset()
    noise = {"observation_adversary": GaussianAdversary(std=0.1)}
    fns = [view_factory(ENV, "protagonist", noise, preset="state-gauss-0.1") for _ in range(n)]
    vector = VectorView(fns)
    vector.seed(0)
    vector.reset()

    def run(env_step: Callable[[np.ndarray], Any], actions: np.ndarray) -> float:
        batches = actions[: len(actions) // n * n].reshape(-1, n, actions.shape[1])
        start = time.perf_counter()
        for batch in batches:
            env_step(batch)
        return time.perf_counter() - start

    return {
        "sync": functools.partial(run, sync.step),
        "dummy": functools.partial(run, dummy.step),
        "vector": functools.partial(run, vector.step),
    }


def runners(
    chunk: int, rng: np.random.Generator, n: int = 8
) -> dict[str, Callable[[np.ndarray], float]]:
    """The stepping loops, each timing one segment of `chunk` (env) steps."""
    view = SingleAgentView(
        advgame.make(ENV, preset="state-gauss-0.1"),
        "protagonist",
        {"observation_adversary": GaussianAdversary(std=0.1)},
    )
    adv_obs = rng.uniform(-1, 1, (chunk, 17)).astype(np.float32)
    adv_act = rng.uniform(-1, 1, (chunk, 6)).astype(np.float32)
    return {
        "raw": _gym_runner(gym.make(ENV)),
        "wrapper": _gym_runner(_NoiseWrapper(gym.make(ENV))),
        "view": _gym_runner(view),
        "parallel": _parallel_runner(adv_obs, adv_act),
        **_vector_runners(n),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=100)
    parser.add_argument("--chunk", type=int, default=1000, help="env steps per segment")
    parser.add_argument("--n", type=int, default=8, help="envs of the vectorised pair")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (args.chunk, 6)).astype(np.float32)
    loops = runners(args.chunk, rng, args.n)
    seconds: dict[str, list[float]] = {k: [] for k in loops}
    for r in range(args.rounds):
        for key, run in loops.items():
            seconds[key].append(run(actions))
        if (r + 1) % max(args.rounds // 10, 1) == 0:
            print(f"round {r + 1}/{args.rounds}", flush=True)
    report(seconds, args.chunk)


def report(seconds: dict[str, list[float]], chunk: int) -> dict[str, Any]:
    """Print (and return) per-round ratio quartiles and the median extra µs per step."""
    raw = np.asarray(seconds["raw"])
    rounds = len(raw)
    print(
        f"\n{ENV}: {rounds} interleaved rounds of {chunk} steps each "
        f"(raw: median {np.median(chunk / raw):,.0f} steps/s)"
    )
    print(
        f"  {'':38s} {'ratio to raw: q25':>17s} {'median':>7s} {'q75':>6s}  {'extra µs/step':>13s}"
    )
    sync = np.asarray(seconds["sync"])
    print(f"  (SyncVectorEnv of raw envs: median {np.median(chunk / sync):,.0f} env steps/s)")
    out: dict[str, Any] = {}
    labels = {
        "wrapper": "plain gym wrapper + N(0,0.1) (reference)",
        "view": "protagonist view + N(0,0.1)",
        "parallel": "ParallelEnv, obs+act advs",
    }
    labels["dummy"] = "DummyVecEnv + plain wrapper (reference)"
    labels["vector"] = "VectorView + N(0,0.1), vs SyncVectorEnv"
    for key, label in labels.items():
        vectorised = key in ("dummy", "vector")
        t, base = np.asarray(seconds[key]), np.asarray(seconds["sync"]) if vectorised else raw
        q25, med, q75 = np.percentile(base / t, [25, 50, 75])
        extra = float(np.median((t - base) / chunk)) * 1e6
        goal = f"  (goal >= {GOALS[key]})" if key in GOALS else ""
        print(f"  {label:40s} {q25:15.3f} {med:7.3f} {q75:6.3f}  {extra:13.1f}{goal}")
        out[key] = {"median": float(med), "q25": float(q25), "q75": float(q75), "extra_us": extra}
    return out


if __name__ == "__main__":
    main()
