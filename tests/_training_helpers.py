"""Shared by the alternation-loop tests (tests/test_training_*.py): tiny training configs, and
readers of a run directory's progress, state, checkpoints and final protagonist."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import torch

from advgame.agents.common.checkpoint import SB3Checkpoint, _algo_class
from advgame.core.config import load_json
from advgame.training import METHODS, TrainConfig

HOPPER = "Hopper-v5"
PENDULUM = "InvertedPendulum-v5"
OFF_POLICY = {"learning_starts": 32, "buffer_size": 2_000, "batch_size": 32}
TINY: dict[str, Any] = {
    "iterations": 2,
    "protagonist_steps": 128,
    "adversary_steps": 128,
    "protagonist_hparams": {"n_steps": 64},
    "adversary_hparams": {"n_steps": 64},
    "eval_episodes": 1,
}
AGENT = "observation_adversary"


def config(method: str, **changes: Any) -> TrainConfig:
    return TrainConfig(**{"scenario": HOPPER, **TINY, **METHODS[method], **changes})


def progress_rows(run: Path) -> list[dict[str, str]]:
    with (run / "progress.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def state(run: Path) -> dict[str, Any]:
    return json.loads((run / "state.json").read_text())


def parameters(zip_path: Path, algo: str) -> dict[str, torch.Tensor]:
    model = _algo_class(algo).load(str(zip_path), device="cpu")
    return {k: v.detach().clone() for k, v in model.policy.state_dict().items()}


def same_parameters(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def final_protagonist(run: Path) -> SB3Checkpoint:
    cfg = load_json(TrainConfig, run / "config.json")
    folder = run / state(run)["checkpoint"]
    return SB3Checkpoint(
        str(folder / "protagonist.zip"),
        cfg.protagonist_algo,
        str(folder / "protagonist_obs_norm.npz"),
        deterministic=True,
    )


def final_learning_rate(run: Path, algo: str) -> float:
    folder = run / state(run)["checkpoint"]
    model = _algo_class(algo).load(str(folder / "protagonist.zip"), device="cpu")
    return float(model.lr_schedule(0.0))  # at the end of the last learn() call
