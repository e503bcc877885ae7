"""An adversary's training views against a frozen LSTM victim: NumPy's group step beside torch's.

What the optimal-attack search and ATLA's adversary phase run against a recurrent protagonist:
``--n-envs`` observation-adversary views of Hopper-v5 (preset ``atla``) in one `VectorView`
(``exact=False``, as training views are), the victim an untrained sb3-contrib ``RecurrentPPO``
(one 64-unit LSTM per network, ATLA's LSTM policy) played deterministically, the adversary's
actions random. Every vector step asks the victim's copies for their actions in one
`RecurrentSB3Policy.act_group` call: in NumPy (`advgame.core.numpy_lstm.LSTMCell.step`, the
default) or through sb3-contrib's torch forward pass (``torch``: the NumPy pass switched off).
Rounds of ``--steps`` vector steps interleave the two; printed: the median environment steps
per second of each and their ratio, with the calibration (a raw HalfCheetah-v5 step) before
and after. One torch thread, as training workers run.

Run: ``python benchmarks/bench_lstm_victim.py [--rounds 3] [--steps 2000] [--n-envs 4]``.
Needs quiet cores.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from calibrate import line, step_us
from sb3_contrib import RecurrentPPO

from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.agents.common.recurrent_policy import RecurrentSB3Policy
from advgame.core.vector import VectorView
from advgame.core.views import view_factory


def _rate(venv: VectorView, steps: int, numpy_pass: bool) -> float:
    """Environment steps per second over `steps` vector steps, random adversary actions."""
    saved = RecurrentSB3Policy._group_net
    if not numpy_pass:
        RecurrentSB3Policy._group_net = lambda self: None  # type: ignore[method-assign]
    try:
        rng = np.random.default_rng(0)
        low, high = venv.action_space.low, venv.action_space.high
        venv.reset()
        began = time.perf_counter()
        for _ in range(steps):
            venv.step(rng.uniform(low, high, size=(venv.num_envs, *low.shape)).astype(np.float32))
        return steps * venv.num_envs / (time.perf_counter() - began)
    finally:
        RecurrentSB3Policy._group_net = saved  # type: ignore[method-assign]


def main() -> None:
    """Print both rates and their ratio."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=2000, help="vector steps per round and pass")
    ap.add_argument("--n-envs", type=int, default=4)
    args = ap.parse_args()
    torch.set_num_threads(1)
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "victim.zip"
        kwargs = {"lstm_hidden_size": 64, "net_arch": []}
        RecurrentPPO("MlpLstmPolicy", gym.make("Hopper-v5"), policy_kwargs=kwargs, seed=0).save(
            path
        )
        victim = SB3Checkpoint(str(path), "recurrent-ppo")
        make = view_factory(
            "Hopper-v5", "observation_adversary", {"protagonist": victim}, preset="atla"
        )
        fns = [make] * args.n_envs
        venv = VectorView(fns, exact=False)
        rates: dict[str, list[float]] = {"numpy": [], "torch": []}
        for r in range(args.rounds):
            for name in rates:
                rates[name].append(_rate(venv, args.steps, numpy_pass=name == "numpy"))
                print(f"round {r}: {name:5s} {rates[name][-1]:7.0f} env steps/s")
        venv.close()
    fast, slow = (statistics.median(rates[k]) for k in ("numpy", "torch"))
    print(
        f"\nadversary views vs an LSTM victim, {args.n_envs} envs: NumPy group step {fast:.0f}, "
        f"torch {slow:.0f} env steps/s: {fast / slow:.2f} x"
    )
    print(line(step_us(steps=5000, repeats=3), 5000, 3, os.getloadavg()[0]))


if __name__ == "__main__":
    main()
