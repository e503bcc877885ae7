"""The causal campaign's learners' training speed on RS-LiftCausal, side by side in one run (issue 39).

Each learner trains on a view of ``RS-LiftCausal`` (preset ``spurious-xnr``, the campaign's
training correlation; one env, as the campaign runs) with its campaign settings: SAC with the
paper's SAC table (`advgame.agents.SACConfig`), RSC (`advgame.agents.RSCConfig`: its world
model and augmentation, which start after ``--warmup`` world-model updates here so that the
timed steps are the campaign's steady state) and DBC (`advgame.agents.DBCConfig`). A variant
``rsc (F.gumbel_softmax)`` draws RSC's relaxed graphs with torch's two-class
``gumbel_softmax`` instead of the logistic-noise sigmoid `CausalWorldModel.sample_graph` uses
(the same distribution), to show what that costs. Each model first takes ``--start`` random
steps and ``--warmup`` learning steps, untimed (imports, robosuite's start and the warm-up
are not in the rate), then ``--steps`` timed learning steps; rounds interleave the learners.
Printed: learning steps per second (median over rounds), RSC's split of its wall time (world
model, SAC step, the rest), and the calibration (a raw HalfCheetah-v5 step) before and after.
One torch thread, as training workers run.
Run: ``python benchmarks/bench_causal.py [--steps 500] [--rounds 2]``. Needs quiet cores.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections import defaultdict
from typing import Any

import torch
from _common import clock_method
from calibrate import line, step_us

from advgame.agents import DBCConfig, RSCConfig, SACConfig
from advgame.core.vector import VectorView
from advgame.core.views import view_factory

SCENARIO, PRESET = "RS-LiftCausal", "spurious-xnr"


def _gumbel_softmax_graph(model: Any) -> None:
    """Make `model`'s world model draw graphs with torch's two-class ``gumbel_softmax``."""
    from torch.nn import functional as F

    world = model.world_model

    def sample_graph(rows: int) -> torch.Tensor:
        logits = world.graph_logits.expand(rows, *world.graph_logits.shape)
        two = torch.stack([logits, torch.zeros_like(logits)], dim=-1)
        return F.gumbel_softmax(two, tau=world.temperature, hard=False, dim=-1)[..., 0]

    world.sample_graph = sample_graph


def _model(kind: str, start: int, warmup: int, seed: int) -> Any:
    venv = VectorView([view_factory(SCENARIO, "protagonist", preset=PRESET)])
    if kind == "sac":
        config: Any = SACConfig(learning_starts=start)
    elif kind == "dbc":
        config = DBCConfig(learning_starts=start)
    else:
        config = RSCConfig(learning_starts=start, model_warmup=warmup)
    model = config.make_model(venv, seed=seed, total_steps=10**6)
    if kind == "rsc (F.gumbel_softmax)":
        _gumbel_softmax_graph(model)
    return model


def rate(kind: str, args: argparse.Namespace, seed: int) -> tuple[float, dict[str, float]]:
    """Learning steps per second of `kind` after its untimed start and warm-up."""
    model = _model(kind, args.start, args.warmup, seed)
    clock: dict[str, float] = defaultdict(float)
    if kind.startswith("rsc"):
        for name in ("update_world_model", "_sac_step"):
            clock_method(model, name, clock)
    model.learn(args.start + args.warmup)  # untimed
    clock.clear()
    began = time.perf_counter()
    model.learn(args.steps, reset_num_timesteps=False)
    clock["wall"] = time.perf_counter() - began
    model.get_env().close()
    return args.steps / clock["wall"], dict(clock)


def main() -> None:
    """Time the learners in interleaved rounds and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=500, help="timed learning steps")
    parser.add_argument("--start", type=int, default=200, help="random steps first (untimed)")
    parser.add_argument("--warmup", type=int, default=200, help="learning steps (untimed)")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))
    kinds = ("sac", "rsc", "rsc (F.gumbel_softmax)", "dbc")
    rates: dict[str, list[float]] = defaultdict(list)
    split: dict[str, float] = {}
    for r in range(args.rounds):
        for kind in kinds:
            per_s, clock = rate(kind, args, seed=r)
            rates[kind].append(per_s)
            print(f"round {r}: {kind:<22} {per_s:6.1f} learning steps/s", flush=True)
            if kind == "rsc":
                split = clock
    print(f"\n{SCENARIO} ({PRESET}), {args.steps} timed learning steps, {args.rounds} rounds:")
    for kind in kinds:
        print(f"  {kind:<22} {statistics.median(rates[kind]):6.1f} learning steps/s")
    wall = split["wall"]
    world, sac = split.get("update_world_model", 0.0), split.get("_sac_step", 0.0)
    print(
        f"RSC's wall (last round, {wall:.1f} s): world model {world / wall:.0%}, SAC step "
        f"{sac / wall:.0%}, the rest (augmentation, environment, collection) "
        f"{1 - (world + sac) / wall:.0%}"
    )
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))


if __name__ == "__main__":
    main()
