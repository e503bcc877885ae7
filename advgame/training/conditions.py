"""The paper's in-training evaluation: the deterministic protagonist in named test conditions.

A run whose `TrainConfig.eval_conditions` names test conditions plays, after every iteration
(every `TrainConfig.protagonist_steps` protagonist steps), `TrainConfig.eval_episodes`
deterministic episodes of its protagonist in each, and writes their mean true return into the
run's ``progress.csv`` as ``eval_<name>_return`` (and the evaluation's wall time as
``eval_wall_s``); `advgame.training.loop.Run._quick_eval` calls `play_conditions` in place of
its nominal / attacked pair. The curves over seeds are what the Robust Gymnasium paper's
Figure 3 draws (`advgame.workflows.campaign_status.evaluation_curves`).

A condition is one of:

* ``"preset:NAME"``: the scenario's preset NAME with the preset's fixed adversaries (a causal
  task's ``spurious-*`` correlation, Hopper's ``default``: OMPO's nominal body). Episode ``k``
  is episode ``1 + k`` of any per-episode schedule, as in the evaluation tables.
* ``"training"``: the run's own game and adversaries (its fixed ones and the latest learned
  ones, at full budget), every episode held at the point of each per-episode schedule that the
  protagonist trains on now (OMPO's shifting body where its training has reached).

Every point plays the same episode seeds (``seed + 200_000 + k``), so a curve moves with the
policy alone.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from advgame.errors import ConfigError, did_you_mean

__all__ = [
    "EVAL_FIELDS",
    "TRAINING",
    "check_conditions",
    "check_presets",
    "condition_column",
    "condition_name",
    "play_conditions",
    "training_schedule",
]

TRAINING = "training"
"""The condition of the run's own game at the schedules' current point."""
EVAL_FIELDS = ("eval_episodes", "eval_conditions")
"""`TrainConfig` fields that say how a run is evaluated during training and change nothing it
learns: a campaign may change them for a run that resumes (`advgame.training.resume`)."""
SEED_OFFSET = 200_000
"""Episode ``k`` of every point resets with ``seed + SEED_OFFSET + k``."""


def condition_name(spec: str) -> str:
    """The name of condition `spec` in the column names: the preset's name, or ``training``."""
    return spec.removeprefix("preset:")


def condition_column(spec: str) -> str:
    """The ``progress.csv`` column of condition `spec`'s mean true return."""
    return f"eval_{condition_name(spec)}_return"


def check_conditions(conditions: Any, episodes: int) -> None:
    """Refuse malformed `conditions` (see the module doc) or conditions with no episodes."""
    if conditions is None:
        return
    good = isinstance(conditions, (list, tuple)) and all(
        isinstance(c, str) and (c == TRAINING or (c.startswith("preset:") and len(c) > 7))
        for c in conditions
    )
    if not good or not conditions:
        raise ConfigError(
            f"TrainConfig.eval_conditions must be a non-empty list of 'preset:NAME' or "
            f"'training', got {conditions!r} (e.g. ['preset:spurious-hhl', 'preset:spurious-hhr'])."
        )
    names = [condition_name(c) for c in conditions]
    if len(set(names)) != len(names):
        raise ConfigError(f"TrainConfig.eval_conditions names a condition twice: {conditions!r}.")
    if episodes < 1:
        raise ConfigError(
            f"TrainConfig.eval_conditions needs eval_episodes >= 1 (episodes per condition and "
            f"point), got {episodes!r}."
        )


def check_presets(scenario: str, conditions: Sequence[str] | None) -> None:
    """Refuse a ``preset:NAME`` condition that `scenario` has no preset for, before training."""
    from advgame.core.registry import scenario_spec

    wanted = [condition_name(c) for c in conditions or () if c != TRAINING]
    presets = scenario_spec(scenario).load_presets() if wanted else {}
    for name in wanted:
        if name not in presets:
            raise ConfigError(
                f"TrainConfig.eval_conditions names preset:{name}, not a preset of "
                f"{scenario}.{did_you_mean(name, presets)} Presets: {sorted(presets)}."
            )


def play_conditions(
    trainer: Any,
    protagonists: Mapping[str, Any],
    schedule: Mapping[str, int],
    games: dict[str, Any],
) -> dict[str, float]:
    """Each condition's mean true return of the deterministic `protagonists` (one point).

    `trainer` gives the run's config, fixed and learned adversaries; `schedule` is where the
    protagonist's training views' per-episode schedules are now (`advgame.core.episodes.
    schedule_positions`), for the ``training`` condition. `games` keeps each condition's game
    from one point to the next (a robosuite task takes seconds to build); the caller closes
    them.
    """
    import time

    cfg, start = trainer.cfg, time.perf_counter()
    row: dict[str, float] = {}
    for spec in cfg.eval_conditions:
        if spec not in games:
            games[spec] = _game(cfg, spec)
        game = games[spec]
        if spec == TRAINING:
            latest = {a: trainer.latest.get(a, trainer.population.of(a)[-1].spec)
                      for a in trainer.learned}  # fmt: skip
            others: dict[str, Any] = {**trainer.fixed, **latest}
            index = max(schedule.values()) if schedule else 1
            indices = [index] * cfg.eval_episodes
        else:
            others = dict(game.preset.adversaries) if game.preset is not None else {}
            indices = list(range(1, cfg.eval_episodes + 1))
        returns = _play(game, {**protagonists, **others}, cfg.seed + SEED_OFFSET, indices)
        row[condition_column(spec)] = float(np.mean(returns))
    row["eval_wall_s"] = time.perf_counter() - start
    return row


def _game(cfg: Any, spec: str) -> Any:
    """The game of condition `spec` for the run of `cfg` (evaluation phase, full budgets)."""
    from advgame.core.registry import make

    if spec == TRAINING:
        return make(cfg.scenario, **cfg.game_options(), phase="eval")
    return make(cfg.scenario, preset=condition_name(spec), phase="eval", **(cfg.task_options or {}))


def _play(game: Any, policies: Mapping[str, Any], seed: int, indices: Sequence[int]) -> list[float]:
    """True returns of episodes ``k`` (seed ``seed + k``, schedule episode ``indices[k]``)."""
    from advgame.core.episodes import build_policies, rollout_batch

    built = build_policies(game, policies)
    return [
        rollout_batch([game], [built], [seed + k], [index])[0].true_return
        for k, index in enumerate(indices)
    ]


def training_schedule(side: Any) -> dict[str, int]:
    """Where the per-episode schedules of `side`'s first training view are (``{agent: i}``).

    Empty for a side without SB3 views (a team learner) or without schedules.
    """
    venv = getattr(side, "venv", None)
    if venv is None:
        return {}
    positions = venv.env_method("schedule_positions")
    return dict(positions[0]) if positions else {}
