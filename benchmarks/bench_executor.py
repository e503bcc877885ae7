"""Executors side by side: the same payoff table on 1 and 2 workers, local pool vs Ray core.

The table: HalfCheetah-v5, two untrained SB3 PPO checkpoints (loaded through `SB3Checkpoint`,
so each step pays a torch forward pass) × three adversary columns (nominal, state noise
N(0, 0.1), action noise N(0, 0.15)), ``--seeds`` seeds of one ``--steps``-step episode per
cell: 2 × 3 × 4 = 24 units (one per cell and seed), i.e. >= 3 units per worker at W = 2.

Each round runs the four variants interleaved (local W=1, Ray W=1, local W=2, Ray W=2) on one
local Ray started once with 2 CPUs (its worker processes stay warm across rounds, as on a real
cluster); the local pool is created inside the timed region, as `evaluate` does. Every
variant must give the same rows. Printed per variant (medians over rounds; ratios are the
medians of per-round ratios, as the machine's speed drifts between rounds): wall time, the
speed-up of W=2 over W=1, the Ray/local ratio, per-unit start-up (from a unit's start to its
protagonist's first action; cold = a worker's first unit in round 1, warm = its later
units), and the share of worker time idle (``1 - Σ unit time / (W × wall)``).

Ray's per-job overhead: ``--trivial`` no-op units on 2 workers, ``wall × W / N`` per unit,
for both executors (the local pool's includes starting its processes, Ray's does not).
Run: ``python benchmarks/bench_executor.py [--seeds 4 --steps 300 --rounds 2]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from _common import make_checkpoints

from advgame.evaluation import AdversarySetup, evaluate, population_jobs
from advgame.runner.run import UnitRecord, run_units

ENV = "HalfCheetah-v5"
VARIANTS = (("local", 1), ("ray", 1), ("local", 2), ("ray", 2))


def columns() -> dict[str, AdversarySetup]:
    return {
        "nominal": AdversarySetup.nominal(),
        "state-gauss-0.1": AdversarySetup.from_preset(ENV, "state-gauss-0.1"),
        "action-gauss-0.15": AdversarySetup.from_preset(ENV, "action-gauss-0.15"),
    }


def records(folder: Path) -> list[dict[str, Any]]:
    import json

    return [json.loads(line) for line in (folder / "jobs.jsonl").read_text().splitlines()]


def idle_share(recs: list[dict[str, Any]], workers: int, wall: float) -> float:
    busy = sum(r["end"] - r["start"] for r in recs)
    return 1.0 - busy / (workers * wall)


def startup_ms(recs: list[dict[str, Any]]) -> tuple[float, float]:
    """Median start-up of each worker's first unit (cold) and of its later units (warm)."""
    seen: set[int] = set()
    cold, warm = [], []
    for r in sorted(recs, key=lambda r: r["start"]):
        (warm if r["pid"] in seen else cold).append(1000 * r["startup_s"])
        seen.add(r["pid"])
    return float(np.median(cold)), float(np.median(warm)) if warm else float("nan")


def overhead_ms(executor: str, n: int) -> float:
    start = time.perf_counter()
    out: list[UnitRecord] = run_units(abs, list(range(n)), executor=executor, workers=2)
    assert [r.value for r in out] == list(range(n))
    return 1000 * (time.perf_counter() - start) * 2 / n


def main() -> None:
    import ray

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--steps", type=int, default=300, help="episode length (time limit)")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--trivial", type=int, default=200, help="no-op units for the overhead")
    args = parser.parse_args()
    here = str(Path(__file__).resolve().parent)
    ray.init(num_cpus=2, include_dashboard=False, runtime_env={"env_vars": {"PYTHONPATH": here}})
    # (no-op units are `abs`: a builtin every worker can import)
    results: dict[tuple[str, int], list[tuple[float, float, float, float]]] = {
        v: [] for v in VARIANTS
    }
    with tempfile.TemporaryDirectory() as tmp:
        jobs = population_jobs(
            ENV, make_checkpoints(Path(tmp), ENV), columns(), seeds=range(args.seeds)
        )
        jobs = [j.__class__(**{**j.__dict__, "make_kwargs": {**j.make_kwargs, "max_episode_steps": args.steps}})
                for j in jobs]  # fmt: skip
        reference = None
        for r in range(args.rounds):
            for kind, w in VARIANTS:
                out = Path(tempfile.mkdtemp(dir=tmp))
                start = time.perf_counter()
                table = evaluate(jobs, workers=w, progress=False, executor=kind, results_dir=out)
                wall = time.perf_counter() - start
                reference = reference or table.rows
                assert table.rows == reference, f"{kind} with {w} workers changed the results"
                recs = records(out)
                results[kind, w].append((wall, idle_share(recs, w, wall), *startup_ms(recs)))
                print(f"round {r + 1}: {kind:5s} W={w} {wall:6.2f} s, idle {results[kind, w][-1][1]:.0%}, "
                      f"load average {os.getloadavg()[0]:.2f}")  # fmt: skip
    med = {v: np.median(np.array(rs), axis=0) for v, rs in results.items()}
    units = len(jobs) * args.seeds
    print(f"\n{ENV}: {len(jobs)} cells × {args.seeds} seeds = {units} units of one {args.steps}-step "
          f"episode; {os.cpu_count()} CPUs; {args.rounds} interleaved rounds; rows identical")  # fmt: skip
    print("  medians over rounds (ratios: median of the per-round ratios)")
    print("  executor  W   wall s  W2/W1  ray/local  start-up ms (1st round cold / warm)  idle")
    for kind, w in VARIANTS:
        walls = np.array([r[0] for r in results[kind, w]])
        speed = np.median(np.array([r[0] for r in results[kind, 1]]) / walls)
        ratio = np.median(walls / np.array([r[0] for r in results["local", w]]))
        cold = results[kind, w][0][2]
        print(f"  {kind:8s} {w:2d} {med[kind, w][0]:8.2f} {speed:6.2f}x {ratio:8.2f}   "
              f"{cold:9.1f} / {med[kind, w][3]:6.1f}                  {med[kind, w][1]:5.0%}")  # fmt: skip
    for kind in ("local", "ray"):
        print(f"  per-job overhead, {kind:5s}: {overhead_ms(kind, args.trivial):6.1f} ms "
              f"({args.trivial} no-op units on 2 workers)")  # fmt: skip
    ray.shutdown()


if __name__ == "__main__":
    main()
