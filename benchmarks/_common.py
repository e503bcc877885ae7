"""Helpers shared by the benchmark and reproduction scripts."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
from calibrate import step_through as step_through  # re-exported: the one stepping loop

from advgame.evaluation.table.payoff import ci95


def fmt(values: list[float]) -> str:
    """``"mean ± half-width"`` of `values` (95 % Student-t interval), rounded to integers."""
    return f"{float(np.mean(values)):.0f} ± {ci95(values):.0f}"


def quartiles(values: list[float]) -> str:
    """``"median (q1-q3)"`` of `values`, two decimals: how the per-round ratios are reported."""
    q1, q2, q3 = np.percentile(values, [25, 50, 75])
    return f"{q2:.2f} ({q1:.2f}-{q3:.2f})"


def median_span(values: list[float], base: list[float]) -> str:
    """``"median (min-max)"`` of the per-round ratios ``values[i] / base[i]``, two decimals."""
    import statistics

    ratios = [v / b for v, b in zip(values, base, strict=True)]
    return f"{statistics.median(ratios):.2f} ({min(ratios):.2f}-{max(ratios):.2f})"


def clock_method(obj: Any, name: str, clock: dict[str, float]) -> None:
    """Wrap method `name` of `obj` so that its wall time accumulates in ``clock[name]``.

    Set on the instance, so it wins over the class's method wherever the object calls
    ``self.name(...)`` (SB3 calls ``self.train``).
    """
    inner = getattr(obj, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            clock[name] += time.perf_counter() - start

    setattr(obj, name, wrapper)


def ratio_row(name: str, rates: dict[str, list[float]]) -> str:
    """A Markdown row: median raw steps/s, then every other variant's per-round ratio to raw.

    `rates` maps ``"raw"`` and each variant to its steps/s in the same interleaved rounds.
    """
    import statistics

    cells = [
        quartiles([v / w for v, w in zip(values, rates["raw"], strict=True)])
        for key, values in rates.items()
        if key != "raw"
    ]
    return f"| {name} | {statistics.median(rates['raw']):.0f} | " + " | ".join(cells) + " |"


def time_game(game: Any, actions: np.ndarray, rng: np.random.Generator) -> float:
    """Wall seconds of `game` playing `actions` as its protagonist; resets inside the timing.

    Each row is cut to the protagonist's action size; every adversary sends uniform random
    actions in ``[-1, 1]``, drawn before timing.
    """
    adv = {
        a: rng.uniform(-1, 1, (len(actions), *game.action_space(a).shape)).astype(np.float32)
        for a in game.adversaries
    }
    size = game.action_space("protagonist").shape[0]
    start, i = time.perf_counter(), 0
    while i < len(actions):
        if not game.agents:
            game.reset()
        move = {a: adv[a][i] for a in game.next_movers if a in adv}
        if "protagonist" in game.next_movers:
            move["protagonist"] = actions[i][:size]
            i += 1
        game.play(move)
    return time.perf_counter() - start


def raw_vs_game(
    time_raw: Callable[[np.ndarray], float],
    plain: Any,
    attacked: Any,
    draw: Callable[[], np.ndarray],
    rounds: int,
    rng: np.random.Generator,
) -> dict[str, list[float]]:
    """Steps/s of the raw env, the game without and with adversaries, in interleaved rounds.

    Each round draws its protagonist actions with `draw` and plays them in all three.
    """
    out: dict[str, list[float]] = {"raw": [], "game": [], "game+adv": []}
    for _ in range(rounds):
        actions = draw()
        steps = len(actions)
        out["raw"].append(steps / time_raw(actions))
        out["game"].append(steps / time_game(plain, actions, rng))
        out["game+adv"].append(steps / time_game(attacked, actions, rng))
    return out


def ratio_table(
    label: str,
    ids: Iterable[str],
    bench: Callable[[str, int, int, int], dict[str, list[float]]],
    steps: int,
    rounds: int,
) -> None:
    """Print a Markdown table of `ratio_row` per id (each row as soon as it is measured)."""
    lines = [
        f"{rounds} interleaved rounds of {steps} steps; raw: median steps/s; "
        "game, game+adv: median per-round ratio to raw (quartiles)",
        f"| {label} | raw steps/s | game / raw | game+adv / raw |",
        "|---|---|---|---|",
    ]
    for sid in ids:
        lines.append(ratio_row(sid, bench(sid, steps, rounds, 0)))
        print(lines[-1], flush=True)
    print("\n".join(lines))


def make_checkpoints(folder: Path, env: str) -> dict[str, Any]:
    """Two untrained SB3 PPO checkpoints of `env` (seeds 1 and 2), saved in `folder`."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    from advgame.agents.common.checkpoint import SB3Checkpoint

    out = {}
    for seed in (1, 2):
        path = folder / f"ppo_{seed}.zip"
        PPO("MlpPolicy", gym.make(env), seed=seed, device="cpu").save(path)
        out[f"ppo-init-{seed}"] = SB3Checkpoint(str(path), algo="ppo")
    return out
