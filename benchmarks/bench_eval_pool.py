"""Population evaluation in a 2-worker process pool vs in-process, side by side in one run.

The same jobs both ways: 2 protagonists × 4 adversaries on HalfCheetah-v5 with full 1000-step
episodes, ``--seeds`` seeds × ``--episodes`` episodes per cell (default 4 × 3: 96 episodes,
96k protagonist steps; the pool plays each seed of a cell as its own task, 32 tasks). The
protagonists are two freshly initialised (untrained) SB3 PPO ``MlpPolicy`` networks saved as
checkpoints and loaded through `SB3Checkpoint`, so each step pays a real torch forward pass;
the adversaries are the nominal game, the paper's state noise N(0, 0.1) and action noise
N(0, 0.15), and uniform RARL-style forces.

Each round times ``evaluate(jobs, workers=1)`` and ``evaluate(jobs, workers=2)``; the pool is
created inside the timed region, so worker start-up and checkpoint loading are paid every
round. In the first round the pool also starts the process's forkserver, which imports the
simulators, torch and SB3 once (later pools fork warm workers): its ratio is printed apart.
Rounds alternate so machine noise hits both alike; the best round of each gives the speed-up
(goal >= 1.8x on 2 cores). The rows of both runs must be identical.

Other processes on the machine distort wall times (and with the kernel's session autogroups,
a session's two workers share one session's CPU share), so each round also prints the load
average and the CPU seconds spent: this process's in-process; the workers' in the pool (spawn:
this process's reaped children; forkserver: the forkserver's /proc stat, its own imports
included). ``2 x CPU(in-process) / CPU(pool)`` estimates the speed-up on two idle cores, as the
32 tasks balance well across two workers.
Each round also measures the machine's own ceiling for two processes: ``--spin`` raw
HalfCheetah steps played twice in this process vs once in each of two processes at the same
time. On a virtual machine whose two vCPUs share a physical core (or its turbo budget), two busy
processes each run slower than one alone, and no pool can beat that ratio; the pool's speed-up
is printed beside it.
Run: ``python benchmarks/bench_eval_pool.py [--seeds 4 --episodes 3 --rounds 2]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import make_checkpoints, step_through

from advgame.evaluation import AdversarySetup, PayoffTable, evaluate, population_jobs

ENV = "HalfCheetah-v5"


def adversaries() -> dict[str, AdversarySetup]:
    from advgame.adversaries import UniformAdversary

    return {
        "nominal": AdversarySetup.nominal(),
        "state-gauss-0.1": AdversarySetup.from_preset(ENV, "state-gauss-0.1"),
        "action-gauss-0.15": AdversarySetup.from_preset(ENV, "action-gauss-0.15"),
        "rarl-uniform": AdversarySetup(
            {"preset": "rarl"}, {"force_adversary": UniformAdversary(-5, 5)}
        ),
    }


def forkserver_cpu() -> float:
    """CPU seconds of the forkserver and of the workers it has reaped (0 before it starts)."""
    from multiprocessing import forkserver

    pid = getattr(forkserver._forkserver, "_forkserver_pid", None)  # private; benchmark only
    if pid is None:
        return 0.0
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return sum(int(f) for f in fields[11:15]) / os.sysconf("SC_CLK_TCK")  # utime..cstime


def cpu_seconds(workers: int, start_method: str) -> float:
    """CPU seconds so far of whoever plays: this process, or the pool's workers."""
    if workers > 1 and start_method == "forkserver":
        return forkserver_cpu()
    who = resource.RUSAGE_SELF if workers == 1 else resource.RUSAGE_CHILDREN
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def timed(jobs: list, workers: int, start_method: str) -> tuple[PayoffTable, float, float]:
    """Evaluate; return the table, the wall time and the CPU seconds the players spent."""
    cpu, start = cpu_seconds(workers, start_method), time.perf_counter()
    table = evaluate(jobs, workers=workers, progress=False, start_method=start_method)
    wall = time.perf_counter() - start
    time.sleep(0.5)  # let the forkserver reap the workers
    return table, wall, cpu_seconds(workers, start_method) - cpu


def spin(steps: int) -> float:
    """Step raw HalfCheetah-v5 `steps` times with fixed random actions; return the wall time."""
    import gymnasium as gym
    import numpy as np

    env = gym.make(ENV)
    env.reset(seed=0)
    return step_through(env, np.random.default_rng(0).uniform(-1, 1, (steps, 6)))


def ceiling(steps: int) -> float:
    """Speed-up two processes at once give over one, on the same raw-env work (wall time)."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    with ProcessPoolExecutor(2, get_context("forkserver")) as pool:
        list(pool.map(spin, [100, 100]))  # start both workers before timing
        one = sum(pool.submit(spin, steps).result() for _ in range(2))
        start = time.perf_counter()
        list(pool.map(spin, [steps, steps]))
        two = time.perf_counter() - start
    return one / two


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--start-method", default="forkserver", choices=["forkserver", "spawn"])
    parser.add_argument("--spin", type=int, default=20_000, help="raw steps for the ceiling")
    args = parser.parse_args()
    seeds = tuple(range(args.seeds))
    wall: dict[int, list[float]] = {1: [], 2: []}
    est, ceilings = [], []
    with tempfile.TemporaryDirectory() as tmp:
        jobs = population_jobs(ENV, make_checkpoints(Path(tmp), ENV), adversaries(), seeds=seeds,
                               episodes=args.episodes)  # fmt: skip
        for r in range(args.rounds):
            (one, t1, c1), (two, t2, c2) = (timed(jobs, w, args.start_method) for w in (1, 2))
            assert one.rows == two.rows, "the pool changed the results"
            wall[1].append(t1)
            wall[2].append(t2)
            est.append(2 * c1 / c2)
            ceilings.append(ceiling(args.spin))
            print(f"round {r + 1}/{args.rounds}: wall 1 worker {t1:.2f} s, 2 workers {t2:.2f} s "
                  f"({t1 / t2:.2f}x); CPU {c1:.1f} s vs {c2:.1f} s ({est[-1]:.2f}x estimate); "
                  f"machine ceiling {ceilings[-1]:.2f}x; 1-min load average {os.getloadavg()[0]:.2f}")  # fmt: skip
    steps = sum(row["length"] for row in one.rows)
    best = {w: min(t) for w, t in wall.items()}
    print(f"\n{ENV}: {len(jobs)} jobs = {len(jobs) * len(seeds)} pool tasks, {len(one)} "
          f"episodes, {steps} steps; {os.cpu_count()} CPUs; {args.start_method}; best of "
          f"{args.rounds} rounds; rows identical")  # fmt: skip
    print(f"  in-process (workers=1)   {best[1]:7.2f} s   {steps / best[1]:8,.0f} steps/s")
    print(f"  process pool (workers=2) {best[2]:7.2f} s   {steps / best[2]:8,.0f} steps/s")
    print(f"  speed-up (wall)          {best[1] / best[2]:7.2f}x  (goal >= 1.8x)")
    print(f"  first round (cold start) {wall[1][0] / wall[2][0]:7.2f}x")
    print(f"  CPU-bound estimate       {max(est):7.2f}x  (best round; first {est[0]:.2f}x)")
    print(f"  machine ceiling          {max(ceilings):7.2f}x  (two raw-env processes vs one; "
          f"median {float(np.median(ceilings)):.2f}x)")  # fmt: skip


if __name__ == "__main__":
    main()
