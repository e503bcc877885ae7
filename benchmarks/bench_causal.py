"""The causal campaigns' learners' training speed, side by side in one run (issue 39).

Each learner trains on a view of ``RS-LiftCausal`` (preset ``spurious-xnr``, the campaign's
training correlation; one env, as the campaign runs), and with ``--scenarios`` also of
``RS-DoorCausal`` (preset ``spurious-hhl``), with its campaign settings: SAC with the
paper's SAC table (`advgame.agents.SACConfig`), RSC (`advgame.agents.RSCConfig`: its world
model and augmentation, which start after ``--warmup`` world-model updates here so that the
timed steps are the campaign's steady state) and DBC (`advgame.agents.DBCConfig`). A variant
``rsc (F.gumbel_softmax)`` draws RSC's relaxed graphs with torch's two-class
``gumbel_softmax`` instead of the logistic-noise sigmoid `CausalWorldModel.sample_graph` uses
(the same distribution), to show what that costs; ``rsc (th.bernoulli)`` draws the hard graphs (the
campaigns' ``graph_draws``) with ``th.bernoulli`` in row-major layout, as RSC did before 7 Dec's
session 40, instead of `CausalWorldModel.draw_graph`'s uniform draws laid out output-major. Each
model first takes ``--start`` random steps and ``--warmup`` learning steps, untimed (imports,
robosuite's start and the warm-up are not in the rate), then ``--steps`` timed learning steps;
rounds interleave the learners.
Printed: each task's raw protagonist step (random actions through the advgame view, no
learner), learning steps per second (median over rounds), RSC's split of its wall time (world
model, SAC step, the rest), and the calibration (a raw HalfCheetah-v5 step) before and after.
One torch thread, as training workers run.
Run: ``python benchmarks/bench_causal.py [--steps 500] [--rounds 2]
[--scenarios RS-LiftCausal,RS-DoorCausal] [--kinds sac,rsc,dbc]``. Needs quiet cores.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections import defaultdict
from typing import Any

import numpy as np
import torch
from _common import clock_method, step_through
from calibrate import line, step_us

from advgame.agents import DBCConfig, RSCConfig, SACConfig
from advgame.core.vector import VectorView
from advgame.core.views import view_factory

PRESETS = {"RS-LiftCausal": "spurious-xnr", "RS-DoorCausal": "spurious-hhl"}
"""Each causal task and the training correlation its campaign uses."""
KINDS = ("sac", "rsc", "rsc (F.gumbel_softmax)", "rsc (th.bernoulli)", "dbc")


def _gumbel_softmax_graph(model: Any) -> None:
    """Make `model`'s world model draw graphs with torch's two-class ``gumbel_softmax``."""
    from torch.nn import functional as F

    world = model.world_model

    def sample_graph(rows: int) -> torch.Tensor:
        logits = world.graph_logits.expand(rows, *world.graph_logits.shape)
        two = torch.stack([logits, torch.zeros_like(logits)], dim=-1)
        return F.gumbel_softmax(two, tau=world.temperature, hard=False, dim=-1)[..., 0]

    world.sample_graph = sample_graph


def _bernoulli_graph(model: Any) -> None:
    """Make `model`'s world model draw its hard graphs with ``th.bernoulli``, row-major."""
    world = model.world_model

    def draw_graph(rows: int) -> torch.Tensor:
        probs = world.edge_probabilities().detach()
        return torch.bernoulli(probs.expand(rows, *probs.shape))

    world.draw_graph = draw_graph


def _view(scenario: str) -> Any:
    """A factory of `scenario`'s protagonist view under its campaign's training correlation."""
    return view_factory(scenario, "protagonist", preset=PRESETS[scenario])


def env_step_ms(scenario: str, steps: int, seed: int = 0, untimed: int = 50) -> float:
    """Mean wall ms of one protagonist step of `scenario`'s view, random actions, no learner."""
    env = _view(scenario)()
    env.reset(seed=seed)
    space = env.action_space
    rng = np.random.default_rng(seed)
    actions = rng.uniform(space.low, space.high, (untimed + steps, *space.shape))
    actions = actions.astype(space.dtype)
    step_through(env, actions[:untimed])  # untimed: the first episode's start
    elapsed = step_through(env, actions[untimed:])
    env.close()
    return elapsed / steps * 1e3


def _model(kind: str, scenario: str, start: int, warmup: int, seed: int) -> Any:
    venv = VectorView([_view(scenario)])
    if kind == "sac":
        config: Any = SACConfig(learning_starts=start)
    elif kind == "dbc":
        config = DBCConfig(learning_starts=start)
    else:
        config = RSCConfig(learning_starts=start, model_warmup=warmup)
    model = config.make_model(venv, seed=seed, total_steps=10**6)
    if kind == "rsc (F.gumbel_softmax)":
        _gumbel_softmax_graph(model)
    elif kind == "rsc (th.bernoulli)":
        _bernoulli_graph(model)
    return model


def rate(
    kind: str, scenario: str, args: argparse.Namespace, seed: int
) -> tuple[float, dict[str, float]]:
    """Learning steps per second of `kind` on `scenario` after its untimed start and warm-up."""
    model = _model(kind, scenario, args.start, args.warmup, seed)
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
    parser.add_argument(
        "--scenarios", default="RS-LiftCausal", help=f"comma-separated, of {', '.join(PRESETS)}"
    )
    parser.add_argument("--kinds", default=",".join(KINDS), help="comma-separated learners")
    args = parser.parse_args()
    scenarios, kinds = args.scenarios.split(","), args.kinds.split(",")
    for name, given, known in (("scenario", scenarios, PRESETS), ("kind", kinds, KINDS)):
        for value in given:
            if value not in known:
                parser.error(f"unknown {name} {value!r}; known: {', '.join(known)}")
    torch.set_num_threads(1)
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))
    rates: dict[tuple[str, str], list[float]] = defaultdict(list)
    raw: dict[str, list[float]] = defaultdict(list)
    split: dict[str, dict[str, float]] = {}
    for r in range(args.rounds):
        for scenario in scenarios:
            raw[scenario].append(env_step_ms(scenario, args.steps, seed=r))
            print(f"round {r}: {scenario} raw step {raw[scenario][-1]:.2f} ms", flush=True)
            for kind in kinds:
                per_s, clock = rate(kind, scenario, args, seed=r)
                rates[scenario, kind].append(per_s)
                print(f"round {r}: {scenario} {kind:<22} {per_s:6.1f} learning steps/s", flush=True)
                if kind == "rsc":
                    split[scenario] = clock
    for scenario in scenarios:
        print(
            f"\n{scenario} ({PRESETS[scenario]}), {args.steps} timed learning steps, "
            f"{args.rounds} rounds; raw step {statistics.median(raw[scenario]):.2f} ms:"
        )
        for kind in kinds:
            print(f"  {kind:<22} {statistics.median(rates[scenario, kind]):6.1f} learning steps/s")
        if scenario in split:
            wall = split[scenario]["wall"]
            world = split[scenario].get("update_world_model", 0.0)
            sac = split[scenario].get("_sac_step", 0.0)
            print(
                f"  RSC's wall (last round, {wall:.1f} s): world model {world / wall:.0%}, SAC "
                f"step {sac / wall:.0%}, the rest (augmentation, environment, collection) "
                f"{1 - (world + sac) / wall:.0%}"
            )
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))


if __name__ == "__main__":
    main()
