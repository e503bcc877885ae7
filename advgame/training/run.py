"""Starting and continuing a training run: `train` and `resume`."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from advgame.core.config import load_json, save_json
from advgame.errors import ConfigError
from advgame.training.conditions import EVAL_FIELDS
from advgame.training.config import TrainConfig
from advgame.training.loop import Run
from advgame.training.trainer import Trainer

__all__ = ["resume", "train"]


def train(config: TrainConfig, run_dir: str | Path, progress: bool | str = True) -> Path:
    """Start a new run in `run_dir` (which must not hold one) and train it to the end.

    `progress`: True shows a bar on a terminal and a line per iteration (and every five
    minutes) when stderr is a file; ``"lines"`` always the lines; False nothing.
    """
    run_dir = Path(run_dir)
    if (run_dir / "state.json").exists():
        raise ConfigError(f"{run_dir} already holds a run; use resume (advgame resume {run_dir}).")
    run = Run(Trainer(config, run_dir, progress))  # checks scenario, preset and learners first
    run_dir.mkdir(parents=True, exist_ok=True)
    save_json(config, run_dir / "config.json")
    return run.execute(fresh=True)


def resume(
    run_dir: str | Path, progress: bool | str = True, evaluation: Mapping[str, Any] | None = None
) -> Path:
    """Continue the run in `run_dir` from its last finished iteration (`progress` as `train`).

    `evaluation`: the in-training evaluation to use from now on (`TrainConfig` fields of
    `advgame.training.conditions.EVAL_FIELDS`, which change nothing the run learns), over the
    saved config's; ``config.json`` is rewritten with them, and ``progress.csv`` shows from
    which iteration on they were played.
    """
    run_dir = Path(run_dir)
    if not (run_dir / "config.json").exists():
        raise ConfigError(f"No run in {run_dir} (no config.json).")
    config = load_json(TrainConfig, run_dir / "config.json")
    if evaluation:
        stray = sorted(set(evaluation) - set(EVAL_FIELDS))
        if stray:
            raise ConfigError(
                f"resume(evaluation=...) takes only {list(EVAL_FIELDS)}, got {stray}: the other "
                "fields change what the run learns."
            )
        changed = replace(config, **evaluation)
        if changed != config:
            save_json(changed, run_dir / "config.json")
            config = changed
    return Run(Trainer(config, run_dir, progress)).execute(
        fresh=not (run_dir / "state.json").exists()
    )
