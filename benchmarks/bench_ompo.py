"""OMPO's training speed beside SB3's SAC with the same networks, in one run (issue 38).

Both learn on a raw Gymnasium task (default Hopper-v5, one env, no normalizer) with OMPO's
networks (`advgame.agents.ompo.nets.OMPOPolicy`: [256, 256], LayerNorm + tanh then ELU), batch
256, 3 updates per environment step, the actor and targets every 2nd update: SAC is SB3's
`SAC` with those settings, OMPO is `advgame.agents.ompo.ompo.OMPO` (OMPO's losses, plus its
discriminator: 10 x 20 updates of batch 256 every 1,000 steps). Each first takes `--start`
random steps (no updates), then `--steps` learning steps; the rate is learning steps per wall
second. Where OMPO's time goes is measured by timing its parts inside the same run. One torch
thread (as training workers use). The calibration (a raw HalfCheetah-v5 step) is printed
before and after, so the rates can be scaled to another day's machine.

It also trains OMPO with PyTorch's own tanh and Adam's for-loop kernel (``ompo-torch-tanh``: what
OMPO ran before `advgame.agents.ompo.nets.SigmoidTanh` and the fused Adam), for their speed-up.

Run: ``python benchmarks/bench_ompo.py [--env Hopper-v5] [--steps 2000] [--repeats 2]``.
"""

from __future__ import annotations

import argparse
import os
import time
from collections import defaultdict
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from _common import clock_method
from calibrate import line, step_us
from stable_baselines3 import SAC
from stable_baselines3.common.vec_env import DummyVecEnv

from advgame.agents.ompo.nets import OMPOPolicy, SigmoidTanh
from advgame.agents.ompo.ompo import OMPO

COMMON: dict[str, Any] = {
    "batch_size": 256,
    "gradient_steps": 3,
    "train_freq": 1,
    "learning_rate": 3e-4,
    "ent_coef": "auto_0.2",
    "target_update_interval": 2,
    "device": "cpu",
    "verbose": 0,
}


def rate(kind: str, env_id: str, start: int, steps: int, seed: int) -> tuple[float, dict]:
    """Learning steps per second of `kind` after `start` random steps.

    ``"sac"`` and ``"ompo"`` as above; ``"sac-paper"`` is the campaign's SAC baseline
    (`SACConfig`: the paper's SAC table, [64, 64] ReLU, batch 64, one update per step), for
    budgeting.
    """
    env = DummyVecEnv([lambda: gym.make(env_id)])
    if kind == "sac-paper":
        from advgame.agents import SACConfig

        cfg = SACConfig(learning_starts=start)
        model = cfg.make_model(env, seed=seed, total_steps=start + steps)
    elif kind == "ompo-torch-tanh":
        model = OMPO(OMPOPolicy, env, learning_starts=start, seed=seed,
                     policy_kwargs={"optimizer_kwargs": {"fused": False}}, **COMMON)  # fmt: skip
        _plain(model)
    else:
        cls = SAC if kind == "sac" else OMPO
        model = cls(OMPOPolicy, env, learning_starts=start, seed=seed, **COMMON)
    clock: dict[str, float] = defaultdict(float)
    if kind == "ompo":
        for name in ("train_discriminator", "critic_loss", "_actor_step"):
            clock_method(model, name, clock)
    clock_method(model, "train", clock)  # SB3 calls self.train(...): the instance attribute wins
    model.learn(start)  # the random steps, untimed
    clock.clear()
    began = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    wall = time.perf_counter() - began
    env.close()
    clock["wall"] = wall
    return steps / wall, dict(clock)


def _plain(model: OMPO) -> None:
    """Undo OMPO's two speed choices: torch's tanh (for `SigmoidTanh`), Adam's for-loop kernel."""
    for net in (model.actor, model.critic, model.critic_target, model.discriminator):
        for module in net.modules():
            for name, child in module.named_children():
                if isinstance(child, SigmoidTanh):
                    setattr(module, name, torch.nn.Tanh())
    disc = model.discriminator
    disc.optimizer = torch.optim.Adam(disc.trunk.parameters(), lr=model.disc_lr, fused=False)


def main() -> None:
    """Print SAC's and OMPO's learning steps per second and their ratio, with calibrations."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="Hopper-v5")
    ap.add_argument("--steps", type=int, default=2000, help="learning steps timed per repeat")
    ap.add_argument("--start", type=int, default=1000, help="random steps before learning")
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(1)
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))
    rates: dict[str, list[float]] = defaultdict(list)
    parts: dict[str, list[dict]] = defaultdict(list)
    for r in range(args.repeats):
        for kind in (
            "sac",
            "ompo",
            "ompo-torch-tanh",
            "sac-paper",
        ):  # interleaved, so drift in the machine's speed hits both
            per_s, clock = rate(kind, args.env, args.start, args.steps, seed=r)
            rates[kind].append(per_s)
            parts[kind].append(clock)
            print(f"repeat {r}: {kind:15s} {per_s:6.1f} learning steps/s")
    sac, ompo = float(np.median(rates["sac"])), float(np.median(rates["ompo"]))
    paper = float(np.median(rates["sac-paper"]))
    plain = float(np.median(rates["ompo-torch-tanh"]))
    print(
        f"\n{args.env}: SAC {sac:.1f} steps/s, OMPO {ompo:.1f} steps/s: OMPO/SAC = {ompo / sac:.2f}"
        f" (the campaign's paper-table SAC baseline: {paper:.1f} steps/s)\n"
        f"OMPO with torch's tanh and unfused Adam: {plain:.1f} steps/s: OMPO is "
        f"{ompo / plain:.2f} x that"
    )
    last = parts["ompo"][-1]
    wall = last["wall"]
    disc = last.get("train_discriminator", 0.0)
    critic = last.get("critic_loss", 0.0)
    actor = last.get("_actor_step", 0.0)
    rest = last.get("train", 0.0) - disc - critic - actor
    print(
        f"OMPO's wall (last repeat, {wall:.1f} s): discriminator {disc / wall:.0%}, critic losses "
        f"{critic / wall:.0%}, actor steps {actor / wall:.0%}, other update work {rest / wall:.0%}, "
        f"environment and collection {1 - last.get('train', 0.0) / wall:.0%}"
    )
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))


if __name__ == "__main__":
    main()
