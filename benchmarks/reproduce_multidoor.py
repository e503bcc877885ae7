"""MultiRobustDoor: a protagonist trained against the no-op arm vs one trained in the alternation.

Per seed, on ``RS-MultiRobustDoor`` (robosuite Door with a second Panda as the adversary arm,
200-step episodes, dense reward):

* ``plain``: PPO protagonist, the second arm holding still (its no-op command) throughout;
* ``alternation``: PPO protagonist vs a PPO adversary arm, alternating (RARL style), the same
  protagonist steps plus as many adversary steps.

Each protagonist is then evaluated against the no-op arm and against the learned arm (the
alternation run's final adversary of the same seed). Results: ``<out>/results.json`` and
``<out>/reproduction.md`` (mean ± half-width of a 95 % Student-t interval over seed means).

Run: ``python benchmarks/reproduce_multidoor.py --out docs/reproduction-multidoor`` (the
defaults: 3 seeds in 3 worker processes, 4 iterations of 1024 steps per side, 3 evaluation
episodes per cell; about 40 minutes on the shared 2-core VM under a load average of ~12, and
a few minutes on an idle 4-core machine).
"""

from __future__ import annotations

import argparse
import json
import logging
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np

from advgame.evaluation.table.payoff import ci95

SCENARIO = "RS-MultiRobustDoor"


def fmt(values: list[float]) -> str:
    """``"mean ± half-width"`` with two decimals (returns here are small)."""
    return f"{float(np.mean(values)):.2f} ± {ci95(values):.2f}"


def _train(seed: int, args: argparse.Namespace) -> dict[str, str]:
    from advgame.training import TrainConfig
    from advgame.workflows.suite import _train_or_resume

    common = {
        "scenario": SCENARIO,
        "preset": "default",
        "seed": seed,
        "iterations": args.iterations,
        "protagonist_steps": args.steps,
        "adversary_steps": args.steps,
        "protagonist_hparams": {"n_steps": args.steps},
        "adversary_hparams": {"n_steps": args.steps},
        "eval_episodes": 0,
    }
    runs = {"plain": {**common, "learned": []}, "alternation": {**common, "learned": None}}
    dirs = {}
    for name, fields in runs.items():
        run_dir = Path(args.out) / "runs" / f"{name}-s{seed}"
        _train_or_resume(TrainConfig(**fields), run_dir)
        dirs[name] = str(run_dir)
    return dirs


def _learned_arm(run_dir: Path) -> Any:
    from advgame.agents.common.checkpoint import SB3Checkpoint

    folder = run_dir / json.loads((run_dir / "state.json").read_text())["checkpoint"]
    norm = folder / "arm_adversary_obs_norm.npz"
    return SB3Checkpoint(
        str(folder / "arm_adversary.zip"), "ppo", str(norm) if norm.exists() else None
    )


def _evaluate(seed: int, dirs: dict[str, str], episodes: int) -> dict[str, float]:
    import advgame
    from advgame.core.episodes import rollout
    from advgame.workflows.suite import run_protagonist

    arm = _learned_arm(Path(dirs["alternation"]))
    row: dict[str, float] = dict(arm_motion(Path(dirs["alternation"]).parents[1], seed))
    for name, d in dirs.items():
        protagonist = run_protagonist(Path(d))[1]
        for column, adversaries in (("no-op arm", {}), ("learned arm", {"arm_adversary": arm})):
            game = advgame.make(SCENARIO, preset="default", phase="eval")
            results = rollout(
                game,
                {"protagonist": protagonist, **adversaries},
                seed=10_000 + seed,
                episodes=episodes,
            )
            game.close()
            row[f"{name} | {column}"] = float(np.mean([r.true_return for r in results]))
    return row


def arm_motion(out: Path, seed: int) -> dict[str, float]:
    """How much the learned arm of seed `seed` acts, in one evaluation episode.

    Against the alternation-trained protagonist: the arm's mean |u|, its hand's largest
    displacement (m) and the door handle's final angle (rad).
    """
    import advgame
    from advgame.core.episodes import build_policies
    from advgame.workflows.suite import run_protagonist

    run = out / "runs" / f"alternation-s{seed}"
    game = advgame.make(SCENARIO, preset="default", phase="eval")
    specs = {"protagonist": run_protagonist(run)[1], "arm_adversary": _learned_arm(run)}
    policies = build_policies(game, specs)
    game.reset(seed=10_000 + seed)
    env = game.task.env
    site = env.robots[1].eef_site_id["right"]
    start, sizes, far = env.sim.data.site_xpos[site].copy(), [], 0.0
    while game.agents:
        actions = {a: policies[a].act(game.observe(a)) for a in game.next_movers}
        sizes.append(float(np.abs(np.asarray(actions["arm_adversary"])).mean()))
        game.play(actions)
        far = max(far, float(np.linalg.norm(env.sim.data.site_xpos[site] - start)))
    handle = float(env.sim.data.qpos[env.handle_qpos_addr])
    return {"mean |u|": float(np.mean(sizes)), "max hand displacement": far, "handle": handle}


def _seed_job(seed: int, args: argparse.Namespace) -> dict[str, float]:
    import torch

    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(1)
    return _evaluate(seed, _train(seed, args), args.episodes)


def _markdown(rows: list[dict[str, float]], args: argparse.Namespace, wall: float) -> str:
    lines = [
        "# MultiRobustDoor: training against the adversarial arm",
        "",
        f"Measured with `python benchmarks/reproduce_multidoor.py --seeds {args.seeds} "
        f"--iterations {args.iterations} --steps {args.steps} --episodes {args.episodes}` on a "
        f"shared 2-core VM (no GPU), {wall / 60:.0f} minutes wall: {args.seeds} seeds, "
        f"{args.iterations} iterations of {args.steps} protagonist steps per run (the "
        "alternation run: as many adversary-arm steps again), 200-step episodes, "
        f"{args.episodes} evaluation episodes per cell. True (dense, shaped) return per episode, "
        "mean ± half-width of a 95 % Student-t interval over seed means.",
        "",
        "| protagonist trained | vs no-op arm | vs learned arm |",
        "|---|---|---|",
    ]
    for name in ("plain", "alternation"):
        cells = [fmt([r[f"{name} | {c}"] for r in rows]) for c in ("no-op arm", "learned arm")]
        lines.append(f"| {name} | {cells[0]} | {cells[1]} |")
    lines += [
        "",
        "What the learned arm does (one evaluation episode per seed, against the alternation "
        "protagonist): mean |u| of its normalized command, its hand's largest displacement, the "
        "door handle's final angle.",
        "",
        "| seed | mean \\|u\\| | hand displacement (m) | handle angle (rad) |",
        "|---|---|---|---|",
    ]
    for seed, r in enumerate(rows):
        lines.append(
            f"| {seed} | {r['mean |u|']:.3f} | {r['max hand displacement']:.2f} | "
            f"{r['handle']:.3f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    """Train, evaluate and write the table."""
    import time

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--steps", type=int, default=1024, help="steps per side per iteration")
    parser.add_argument("--episodes", type=int, default=3, help="evaluation episodes per cell")
    parser.add_argument("--workers", type=int, default=3)
    parser.add_argument("--out", default="docs/reproduction-multidoor")
    parser.add_argument(
        "--arm-only", action="store_true", help="only add the arm's motion to existing results"
    )
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    if args.arm_only:
        saved = json.loads((out / "results.json").read_text())
        rows = [{**r, **arm_motion(out, seed)} for seed, r in enumerate(saved["per_seed"])]
        args, wall = argparse.Namespace(**saved["args"]), float(saved["wall_s"])
    else:
        with ProcessPoolExecutor(args.workers, mp_context=get_context("forkserver")) as pool:
            rows = list(pool.map(_seed_job, range(args.seeds), [args] * args.seeds))
        wall = time.perf_counter() - start
    record = {"args": vars(args), "wall_s": wall, "per_seed": rows}
    (out / "results.json").write_text(json.dumps(record, indent=2))
    (out / "reproduction.md").write_text(_markdown(rows, args, wall))
    logging.getLogger(__name__).warning("wrote %s", out / "reproduction.md")


if __name__ == "__main__":
    main()
