"""The array game beside SyncVectorEnv and EnvPool, and a single game beside the raw env, in one run.

Part 1, N copies of a MuJoCo v5 task (``--env``, default HalfCheetah-v5) for N in ``--n``
(default 1, 8, 64), random actions drawn before timing, every variant stepping the same actions:

* ``sync``: Gymnasium's ``SyncVectorEnv`` of N ``gymnasium.make(env)`` over the raw task (1.00),
  with MuJoCo's profiling timers on, as MuJoCo's Python bindings set them.
* ``sync-quiet``: the same with those timers off, as the games run (`advgame.core.mujoco_timers`):
  the games' own cost is the ratio to it; ``sync-quiet / sync`` per round is printed.
* ``floor``: the same N unwrapped envs' simulators stepped by a bare Python loop (controls
  written, ``mj_step``; no observation, reward or game): the least Python per copy of any design
  that keeps one ``MjData`` a copy, so its ratio bounds what the array game reaches on one thread.
* ``array-tK``: `advgame.core.array_game.ArrayGame` of N games of preset ``default`` with
  uniformly random observation and action adversaries (drawn before timing, as the protagonist's
  actions are; a sense and an act call per step, budgets checked, clips counted, finished copies
  reset), K simulator threads.
* ``array-bindings-tK`` (with ``--bindings``): the same array game with its simulator stepped
  by MuJoCo's Python bindings, one call per copy (``ThreadedStepper(native=False)``), instead
  of the compiled loop (`advgame.core.native_step`); its per-round ratio to ``array-tK`` is
  printed.
* ``view-tK``: `advgame.core.vector.VectorView` of N protagonist views of the same games with
  `RandomAdversary` policies embedded (what training steps; on the array game).
* ``lockstep-tK``: the same `VectorView` on its lockstep path (``array=False``: before the array
  game).
* ``envpool-tK``: EnvPool's own ``<env>`` with K threads (absent unless ``import envpool`` works:
  run the script from an environment that has it, e.g. one made with
  ``python -m venv .venv-envpool`` layered over this one and ``pip install envpool``).

Part 2, one copy (on unless ``--no-single``; ``--single-only`` skips part 1): the raw env
(``gymnasium.make``, its wrappers; timers on, and ``raw-quiet`` off), a `Game` of preset
``default`` played through ``play`` (a sense and an act move) and through ``step`` (the
ParallelEnv form: every agent's action in, five per-agent dicts out), and the array game of one
copy; the adversaries' uniform actions are drawn before timing, as the protagonist's are.

The variants are interleaved for ``--rounds`` rounds of ``--chunk`` vector steps and each is
compared with ``sync`` (or the raw env) of the same round. Printed: a calibration line
(`benchmarks/calibrate.py`'s raw HalfCheetah step in µs, with the load average), then the
median env-steps/s of the reference and the quartiles of each variant's per-round ratio to it
(and, where EnvPool ran, the array game's per-round ratio to EnvPool on as many threads),
and for part 2 a second calibration line after it. ``--clock cpu`` times in the process's CPU
time instead of wall time: on shared, loaded cores the ratios are then less noisy (time spent
descheduled does not count), but caches are still shared, so they remain indications.
Run on quiet cores: ``python benchmarks/bench_array_game.py`` (``--env``, ``--n``, ``--threads``,
``--rounds``, ``--chunk``).
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from _common import quartiles
from bench_batch_physics import GameViews
from calibrate import step_us

import advgame
from advgame.core.array_game import ArrayGame
from advgame.core.physics import shared_stepper

ADVERSARIES = ("observation_adversary", "action_adversary")


class _Array:
    """An `ArrayGame` of preset ``default`` whose adversaries play uniform actions.

    As in `_Single`, the adversaries' actions are drawn before timing (a pool cycled through),
    as the protagonist's are: the ratio is the game's own cost, not a policy's.
    """

    def __init__(self, env_id: str, n: int, threads: int, native: bool = True) -> None:
        self.game = ArrayGame(
            [advgame.make(env_id, preset="default") for _ in range(n)], threads=threads
        )
        self.stepper, self.native = shared_stepper(threads), native
        rng = np.random.default_rng(1)
        sizes = {a: (n, *self.game.games[0].action_space(a).shape) for a in ADVERSARIES}
        self.pool = [{a: rng.uniform(-1, 1, s) for a, s in sizes.items()} for _ in range(97)]
        self.i = 0
        self.n = n

    def reset(self, seed: int) -> None:
        self.game.reset(seed=seed)

    def step(self, actions: np.ndarray) -> None:
        game, drawn = self.game, self.pool[self.i]
        self.i = (self.i + 1) % len(self.pool)
        self.stepper.native = self.native  # the process's stepper: this variant's loop
        game.sense({"observation_adversary": drawn["observation_adversary"]})
        game.act({"protagonist": actions, "action_adversary": drawn["action_adversary"]})
        if game.done.any():
            game.reset(rows=game.done)

    def close(self) -> None:
        self.game.close()


class _Single:
    """One `Game` of preset ``default`` played move by move (`Game.play`, or `Game.step`).

    The adversaries' uniform actions are drawn before timing (a pool cycled through), as the
    protagonist's are, so the ratio to the raw env is the game's own cost, not a policy's.
    """

    def __init__(self, env_id: str, pettingzoo: bool = False) -> None:
        self.game = advgame.make(env_id, preset="default")
        rng = np.random.default_rng(1)
        sizes = {a: self.game.action_space(a).shape for a in ADVERSARIES}
        self.pool = [
            {a: rng.uniform(-1, 1, shape) for a, shape in sizes.items()} for _ in range(997)
        ]
        self.i = 0
        self.pettingzoo = pettingzoo

    def reset(self, seed: int) -> None:
        self.game.reset(seed=seed)

    def step(self, actions: np.ndarray) -> None:
        game, drawn = self.game, self.pool[self.i]
        self.i = (self.i + 1) % len(self.pool)
        if self.pettingzoo:  # the ParallelEnv form: every agent's action, five dicts back
            acts = {"protagonist": actions[0], **drawn}
            game.step(acts)
            game.step(acts)
            ended = not game.agents
        else:
            game.play({"observation_adversary": drawn["observation_adversary"]})
            move = game.play(
                {"protagonist": actions[0], "action_adversary": drawn["action_adversary"]}
            )
            ended = move.terminated or move.truncated
        if ended:
            game.reset()

    def close(self) -> None:
        self.game.close()


class _Raw:
    """``gymnasium.make(env)`` stepped one action at a time."""

    def __init__(self, env_id: str) -> None:
        self.env = gym.make(env_id)

    def reset(self, seed: int) -> None:
        self.env.reset(seed=seed)

    def step(self, actions: np.ndarray) -> None:
        _, _, terminated, truncated, _ = self.env.step(actions[0])
        if terminated or truncated:
            self.env.reset()

    def close(self) -> None:
        self.env.close()


class _Floor:
    """N unwrapped envs' simulators stepped by a bare loop: the controls written, ``mj_step``.

    No observation, reward, time limit or reset: the least Python any design that keeps one
    ``MjData`` per copy (as exactness needs: `advgame.core.physics`) runs per copy and step.
    Its ratio to ``sync`` bounds what the array game can reach on one thread.
    """

    def __init__(self, env_id: str, n: int) -> None:
        self.envs = [gym.make(env_id).unwrapped for _ in range(n)]

    def reset(self, seed: int) -> None:
        for i, env in enumerate(self.envs):
            env.reset(seed=seed + i)

    def step(self, actions: np.ndarray) -> None:
        import mujoco

        mj_step = mujoco.mj_step
        for env, a in zip(self.envs, actions, strict=True):
            env.data.ctrl[:] = a
            mj_step(env.model, env.data, env.frame_skip)

    def close(self) -> None:
        for env in self.envs:
            env.close()


SHIPPED = ("sync", "floor", "raw")
"""Variants that run with MuJoCo's profiling timers on, as the bindings set them (`measure`)."""


def _sync(env_id: str, n: int) -> Any:
    return gym.vector.SyncVectorEnv([lambda: gym.make(env_id)] * n)


def _variants(
    env_id: str, n: int, threads: list[int], bindings: bool = False
) -> dict[str, Callable[[], Any]]:
    out: dict[str, Callable[[], Any]] = {
        "sync": functools.partial(_sync, env_id, n),
        "sync-quiet": functools.partial(_sync, env_id, n),
        "floor": functools.partial(_Floor, env_id, n),
    }
    for k in threads:
        out[f"array-t{k}"] = functools.partial(_Array, env_id, n, k)
        if bindings and n > 1:
            out[f"array-bindings-t{k}"] = functools.partial(_Array, env_id, n, k, False)
        if n > 1:
            out[f"view-t{k}"] = functools.partial(GameViews, env_id, n, k, array=True)
            out[f"lockstep-t{k}"] = functools.partial(GameViews, env_id, n, k, array=False)
    try:
        import envpool

        for k in threads:
            out[f"envpool-t{k}"] = functools.partial(
                envpool.make_gymnasium, env_id, num_envs=n, num_threads=k, seed=0
            )
    except ImportError:
        print("envpool is not importable here: its columns are skipped (see the docstring)")
    return out


def measure(
    variants: dict[str, Callable[[], Any]],
    env_id: str,
    n: int,
    rounds: int,
    chunk: int,
    clock: Callable[[], float] = time.perf_counter,
) -> dict[str, list[float]]:
    """Env-steps/s of every variant per round, interleaved, timed by `clock`.

    Before each variant's segment MuJoCo's profiling timers (`advgame.core.mujoco_timers`) are
    set as that variant runs them in a process of its own: on, as MuJoCo's bindings set them,
    for the raw references in `SHIPPED`; off for the games (which switch them off) and for the
    ``-quiet`` references (the same raw envs without them: the game's own cost beside them).
    """
    slot, shipped = _timer_states()
    space = gym.make(env_id).action_space
    assert isinstance(space, gym.spaces.Box)
    actions = np.random.default_rng(0).uniform(space.low, space.high, (chunk, n, *space.shape))
    envs = {name: make() for name, make in variants.items()}
    for name, env in envs.items():
        if name.startswith("envpool"):
            env.reset()  # seeded at construction
        else:
            env.reset(seed=0)
    rates: dict[str, list[float]] = {name: [] for name in envs}
    for _ in range(rounds):
        for name, env in envs.items():
            acts = actions.astype(np.float64 if name.startswith("envpool") else np.float32)
            slot.value = shipped if name in SHIPPED else None
            start = clock()
            for a in acts:
                env.step(a)
            rates[name].append(chunk * n / (clock() - start))
    for env in envs.values():
        env.close()
    return rates


def _timer_states() -> tuple[Any, int]:
    """MuJoCo's ``mjcb_time`` slot and the timer the bindings install in it."""
    import mujoco

    from advgame.core.mujoco_timers import timer_slot

    slot = timer_slot()
    assert slot is not None, "MuJoCo's mjcb_time is not reachable on this platform"
    slot.value = None
    mujoco.MjData(mujoco.MjModel.from_xml_string("<mujoco/>"))  # the bindings set theirs
    assert slot.value, "MuJoCo's bindings no longer set a timer: drop the -quiet columns"
    return slot, slot.value


def _row(label: str, rates: dict[str, list[float]], base: str) -> str:
    cells = [
        quartiles([v / s for v, s in zip(values, rates[base], strict=True)])
        for key, values in rates.items()
        if key != base
    ]
    return f"| {label} | {statistics.median(rates[base]):.0f} | " + " | ".join(cells) + " |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="HalfCheetah-v5")
    parser.add_argument("--n", default="1,8,64")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--chunk", type=int, default=50, help="vector steps per segment")
    parser.add_argument("--no-single", dest="single", action="store_false")
    parser.add_argument(
        "--bindings",
        action="store_true",
        help="add array-bindings-tK: the array game with the simulator stepped by MuJoCo's "
        "Python bindings, one call per copy, instead of the compiled loop",
    )
    parser.add_argument(
        "--single-only", action="store_true", help="only part 2, the single game vs the raw env"
    )
    parser.add_argument(
        "--clock",
        choices=("wall", "cpu"),
        default="wall",
        help="wall time, or the process's CPU time (on loaded cores: time spent descheduled "
        "does not count, though caches are still shared)",
    )
    args = parser.parse_args()
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    threads = [int(k) for k in args.threads.split(",")]
    _calibrate(args.clock)
    for n in [] if args.single_only else [int(x) for x in args.n.split(",")]:
        variants = _variants(args.env, n, threads, args.bindings)
        rates = measure(variants, args.env, n, args.rounds, args.chunk, clock)
        print(f"| {args.env} N | sync steps/s | " + " | ".join(k for k in rates if k != "sync"))
        print(_row(str(n), rates, "sync"))
        ratios = [q / s for q, s in zip(rates["sync-quiet"], rates["sync"], strict=True)]
        print(f"  sync without / with MuJoCo's timers, per round: {quartiles(ratios)}")
        for k in threads:  # the array game against EnvPool directly, round by round
            a, e = rates.get(f"array-t{k}"), rates.get(f"envpool-t{k}")
            if a and e:
                ratios = [x / y for x, y in zip(a, e, strict=True)]
                print(f"  array-t{k} / envpool-t{k}, per round: {quartiles(ratios)}")
            b = rates.get(f"array-bindings-t{k}")
            if a and b:
                ratios = [x / y for x, y in zip(a, b, strict=True)]
                print(f"  array-t{k} / array-bindings-t{k}, per round: {quartiles(ratios)}")
    if args.single or args.single_only:
        single = {
            "raw": lambda: _Raw(args.env),
            "raw-quiet": lambda: _Raw(args.env),
            "game": lambda: _Single(args.env),
            "parallel-env": lambda: _Single(args.env, pettingzoo=True),
            "array-1": lambda: _Array(args.env, 1, 1),
        }
        rates = measure(single, args.env, 1, args.rounds, args.chunk * 8, clock)
        _calibrate(args.clock)  # the load may have moved during the run: before and after
        print(
            f"| {args.env} single ({args.clock} time) | raw steps/s | raw, timers off "
            "| game (`play`) | ParallelEnv (`step`) | array game of one |"
        )
        print(_row("1", rates, "raw"))
        ratios = [g / q for g, q in zip(rates["game"], rates["raw-quiet"], strict=True)]
        print(f"  game / raw with timers off too, per round: {quartiles(ratios)}")


def _calibrate(clock: str) -> None:
    load = os.getloadavg()[0]
    print(
        f"calibration: raw HalfCheetah-v5 step {step_us(5_000, 3):.1f} µs wall "
        f"(load {load:.2f}; this run times in {clock} time)"
    )


if __name__ == "__main__":
    main()
