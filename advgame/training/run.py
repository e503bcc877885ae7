"""Starting and continuing a training run: `train` and `resume`."""

from __future__ import annotations

from pathlib import Path

from advgame.core.config import load_json, save_json
from advgame.errors import ConfigError
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


def resume(run_dir: str | Path, progress: bool | str = True) -> Path:
    """Continue the run in `run_dir` from its last finished iteration (`progress` as `train`)."""
    run_dir = Path(run_dir)
    if not (run_dir / "config.json").exists():
        raise ConfigError(f"No run in {run_dir} (no config.json).")
    config = load_json(TrainConfig, run_dir / "config.json")
    return Run(Trainer(config, run_dir, progress)).execute(
        fresh=not (run_dir / "state.json").exists()
    )
