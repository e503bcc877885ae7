"""The one zero-sum training loop: ATLA/RARL-style alternation over any scenario.

Each iteration reads as three named steps, as in PSRO::

    update_protagonists()   # train the protagonist vs adversaries drawn from the population
    update_adversaries()    # train each learned adversary vs the frozen protagonist
    snapshot()              # checkpoint both sides, grow the population, evaluate, log

A run directory holds everything: ``config.json``, ``state.json`` (the last finished
iteration), ``checkpoints/iter_NNNN/``, ``population.json``, ``progress.csv`` and ``tb/``
(TensorBoard). Every iteration is committed atomically, so a run killed at any moment (even
by SIGKILL) loses at most the iteration in progress; `resume` continues it.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import os
import shutil
import time
import typing
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from advgame.config import load_json, save_json
from advgame.errors import ConfigError
from advgame.learning import EpisodeStats
from advgame.population import Member, Population
from advgame.registry import load, make

__all__ = ["METHODS", "TrainConfig", "Trainer", "learner_config", "resume", "train"]

log = logging.getLogger(__name__)

_LEARNERS = "advgame.agents.sb3:LEARNERS"
_TEAM_LEARNERS = "advgame.agents.marl:MARL_LEARNERS"
TEAM_ALGOS = ("mappo", "ippo")
"""Protagonist learners that train a whole team (MaMuJoCo) instead of one SB3 agent."""
PROTAGONISTS = "protagonists"
"""The key of the protagonist side in `Trainer.sides` (one agent or a whole team)."""
_ZERO = "advgame.adversaries.noise:ZeroAdversary"

METHODS: dict[str, dict[str, Any]] = {
    "ppo": {"preset": "default", "learned": [], "train_budget_scale": 1.0},
    "atla": {"preset": "atla", "learned": None, "train_budget_scale": 1.0},
    "rarl": {"preset": "rarl", "learned": None, "train_budget_scale": 0.5},
}
"""Named starting points: plain PPO on the nominal task, ATLA (learned observation attack in
normalized units) and RARL (learned forces, trained at half the bound, tested at full)."""


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run needs; saved as ``config.json`` in the run directory."""

    scenario: str = "Hopper-v5"
    """Registered scenario id."""
    preset: str = "atla"
    """Scenario preset giving the disruptors (and any fixed adversary policies)."""
    learned: list[str] | None = None
    """Adversary agents trained in the adversary phase (None: every adversary the preset gives
    no fixed policy; []: none, i.e. plain training against fixed or no-op adversaries)."""
    protagonist_algo: Literal["ppo", "sac", "td3", "mappo", "ippo"] = "ppo"
    """Protagonist learner: SB3 PPO/SAC/TD3 for one protagonist, MAPPO/IPPO for a team."""
    adversary_algo: Literal["ppo", "sac"] = "ppo"
    """Learner of each learned adversary."""
    protagonist_hparams: dict[str, Any] | None = None
    """Overrides of the protagonist learner config (e.g. {"n_steps": 512})."""
    adversary_hparams: dict[str, Any] | None = None
    """Overrides of the adversary learner config."""
    iterations: int = 10
    """Alternation iterations."""
    protagonist_steps: int = 2048
    """Protagonist steps per iteration (ATLA: one PPO update of 2048 steps)."""
    adversary_steps: int = 2048
    """Steps per learned adversary per iteration."""
    warmup_steps: int = 0
    """Protagonist steps against no-op adversaries before the first iteration."""
    sampling: Literal["latest", "uniform", "fictitious"] = "latest"
    """How protagonist-phase opponents are drawn from the population: the latest snapshot,
    uniform over all members (the no-op included), or fictitious play (past snapshots)."""
    snapshot_every: int = 1
    """Add the adversaries to the population every this many iterations."""
    train_budget_scale: float = 1.0
    """Scale of every budget while training (RARL trains at a fraction, tests at full)."""
    normalize: bool = True
    """Normalize observations and rewards (VecNormalize) for every learner."""
    n_envs: int = 1
    """Views per learner."""
    vec_env: Literal["dummy", "subproc"] = "dummy"
    """VecEnv kind; "dummy" is faster for cheap MuJoCo tasks on 2 cores."""
    eval_episodes: int = 2
    """Episodes of the quick evaluation logged at every iteration."""
    seed: int = 0
    """Seeds models, environments and population sampling."""

    def __post_init__(self) -> None:
        for name in ("iterations", "protagonist_steps", "n_envs", "snapshot_every"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ConfigError(
                    f"TrainConfig.{name} must be an int >= 1, got {getattr(self, name)!r}."
                )
        for name in ("adversary_steps", "warmup_steps", "eval_episodes"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 0:
                raise ConfigError(
                    f"TrainConfig.{name} must be an int >= 0, got {getattr(self, name)!r}."
                )
        for name in ("protagonist_algo", "adversary_algo", "sampling", "vec_env"):
            allowed = typing.get_args(typing.get_type_hints(TrainConfig)[name])
            if getattr(self, name) not in allowed:
                raise ConfigError(
                    f"TrainConfig.{name} must be one of {allowed}, got {getattr(self, name)!r}."
                )
        if self.learned is not None and (
            isinstance(self.learned, str) or not all(isinstance(a, str) for a in self.learned)
        ):
            raise ConfigError(
                f"TrainConfig.learned must be None or a list of adversary ids, got {self.learned!r}"
                ' (e.g. ["observation_adversary"]).'
            )
        scale = self.train_budget_scale
        if (
            isinstance(scale, bool)
            or not isinstance(scale, (int, float))
            or not 0 < scale < math.inf
        ):
            raise ConfigError(f"train_budget_scale must be a number > 0, got {scale!r}.")
        for name in ("protagonist_hparams", "adversary_hparams"):
            if getattr(self, name) is not None and not isinstance(getattr(self, name), dict):
                raise ConfigError(
                    f"TrainConfig.{name} must be a dict, got {getattr(self, name)!r}."
                )


def learner_config(algo: str, overrides: dict[str, Any] | None) -> Any:
    """The learner config of `algo` with `overrides` applied (unknown names are an error)."""
    from advgame.config import from_dict, to_dict

    learners = {**load(_LEARNERS), **(load(_TEAM_LEARNERS) if algo in TEAM_ALGOS else {})}
    if algo not in learners:
        raise ConfigError(f"Unknown learner {algo!r}; expected one of {sorted(learners)}.")
    base = learners[algo]()
    return from_dict(type(base), {**to_dict(base), **(overrides or {})})


def scaled(spec: Any, factor: float) -> Any:
    """A disruptor spec with its budget multiplied by `factor` (RARL's training fraction)."""
    if factor == 1.0:
        return spec
    changes = {}
    for name in ("eps", "max_force", "max_torque", "alpha", "scale"):
        if hasattr(spec, name):
            value = np.asarray(getattr(spec, name), dtype=float) * factor
            changes[name] = (
                min(float(value), 1.0)
                if name == "alpha"
                else (float(value) if value.ndim == 0 else tuple(value.tolist()))
            )
    return replace(spec, **changes)


class Trainer:
    """Runs (or resumes) the alternation loop of `config` in `run_dir`."""

    def __init__(self, config: TrainConfig, run_dir: str | Path, progress: bool = True) -> None:
        self.cfg = config
        self.dir = Path(run_dir)
        self.progress = progress
        probe = make(config.scenario, preset=config.preset)
        self.protagonists: tuple[str, ...] = probe.protagonists
        self.team = config.protagonist_algo in TEAM_ALGOS
        if len(self.protagonists) > 1 and not self.team:
            raise ConfigError(
                f"{config.scenario} has {len(self.protagonists)} protagonists; train them with "
                f"protagonist_algo='mappo' or 'ippo', not {config.protagonist_algo!r}."
            )
        preset = probe.preset
        self.fixed = dict(preset.adversaries) if preset is not None else {}
        self.learned = (
            list(config.learned)
            if config.learned is not None
            else [a for a in probe.adversaries if a not in self.fixed]
        )
        for a in self.learned:
            if a not in probe.adversaries:
                raise ConfigError(
                    f"learned names {a!r}, not an adversary of this game {probe.adversaries}."
                )
        self.normalized_targets = [
            d for d in probe.disruptors.values() if getattr(d.spec, "space", "raw") == "normalized"
        ]
        probe.close()
        self.train_kwargs = {
            "disruptors": [
                scaled(d.spec, config.train_budget_scale) for d in probe.disruptors.values()
            ]
        }
        self.rng = np.random.default_rng(config.seed)
        self.population = Population()
        self.iteration = 0
        self.sides: dict[str, Any] = {}
        """`PROTAGONISTS` -> the protagonist side; each learned adversary id -> its side."""
        self.latest: dict[str, Any] = {}
        """Each learned adversary's spec as saved this iteration (in the population or not)."""

    # -- the three steps --------------------------------------------------------------------
    def update_protagonists(self, stats: EpisodeStats) -> None:
        """Train the protagonist against opponents drawn from the population."""
        side = self.sides[PROTAGONISTS]
        for i in range(self.cfg.n_envs):
            drawn = {
                a: self._opponent(self.population.sample(a, self.cfg.sampling, self.rng))
                for a in self.learned
            }
            side.set_policies(drawn, index=i)
        self._push_scale(side, side)
        side.learn(self.cfg.protagonist_steps, stats)

    def update_adversaries(self, stats: EpisodeStats, frozen: dict[str, Any]) -> None:
        """Train each learned adversary against the frozen protagonists (and latest fellows).

        `frozen` maps every protagonist id to the spec of its just-saved policy.
        """
        prot = self.sides[PROTAGONISTS]
        prot.freeze()
        for agent in self.learned:
            side = self.sides[agent]
            fellows = {
                a: self._opponent(self.population.of(a)[-1]) for a in self.learned if a != agent
            }
            side.set_policies({**frozen, **fellows})
            self._push_scale(side, prot)
            if self.cfg.adversary_steps:
                side.learn(self.cfg.adversary_steps, stats)

    def snapshot(self, folder: Path) -> None:
        """Save the adversaries, add them to the population every `snapshot_every` iterations."""
        keep = (
            self.iteration % self.cfg.snapshot_every == 0 or self.iteration == self.cfg.iterations
        )
        for agent in self.learned:
            spec = self.sides[agent].save(folder)
            final = replace(
                spec, path=spec.path.replace(".partial", ""), normalizer=_final(spec.normalizer)
            )
            self.latest[agent] = final
            if keep:
                self.population.add(
                    Member(
                        f"{agent}@{self.iteration}",
                        "adversary",
                        agent,
                        final,
                        self.iteration,
                        meta={"scenario": self.cfg.scenario},
                    )
                )

    # -- helpers ----------------------------------------------------------------------------
    def _opponent(self, member: Member) -> Any:
        spec = member.spec
        return replace(spec, deterministic=False) if hasattr(spec, "deterministic") else spec

    def _push_scale(self, side: Any, source: Any) -> None:
        """Give `side`'s games the normalizer std of `source` (the protagonist side)."""
        if not self.normalized_targets:
            return
        std = source.observation_std()
        stds = std if isinstance(std, dict) else {self.protagonists[0]: std}
        if std is not None:
            for target, value in stds.items():
                side.set_observation_scale(target, value)

    def protagonist_specs(self, saved: Any) -> dict[str, Any]:
        """What the protagonist side's `save` returned, as ``{protagonist id: spec}``."""
        return dict(saved) if isinstance(saved, dict) else {self.protagonists[0]: saved}


def _final(path: str | None) -> str | None:
    """The path a file in an ``iter_NNNN.partial`` folder has once the folder is committed."""
    return None if path is None else path.replace(".partial", "")


def train(config: TrainConfig, run_dir: str | Path, progress: bool = True) -> Path:
    """Start a new run in `run_dir` (which must not hold one) and train it to the end."""
    from advgame.loop import Run

    run_dir = Path(run_dir)
    if (run_dir / "state.json").exists():
        raise ConfigError(f"{run_dir} already holds a run; use resume (advgame resume {run_dir}).")
    run = Run(Trainer(config, run_dir, progress))  # checks scenario, preset and learners first
    run_dir.mkdir(parents=True, exist_ok=True)
    save_json(config, run_dir / "config.json")
    return run.execute(fresh=True)


def resume(run_dir: str | Path, progress: bool = True) -> Path:
    """Continue the run in `run_dir` from its last finished iteration."""
    from advgame.loop import Run

    run_dir = Path(run_dir)
    if not (run_dir / "config.json").exists():
        raise ConfigError(f"No run in {run_dir} (no config.json).")
    config = load_json(TrainConfig, run_dir / "config.json")
    return Run(Trainer(config, run_dir, progress)).execute(
        fresh=not (run_dir / "state.json").exists()
    )


def write_state(run_dir: Path, state: dict[str, Any]) -> None:
    """Write ``state.json`` atomically."""
    tmp = run_dir / "state.json.tmp"
    tmp.write_text(json.dumps(state, indent=2) + "\n")
    os.replace(tmp, run_dir / "state.json")


def append_progress(path: Path, row: dict[str, Any], keep_below: int | None = None) -> None:
    """Append a row to the progress CSV; on resume drop rows of iterations >= `keep_below`."""
    rows: list[dict[str, Any]] = []
    if path.exists():
        with path.open() as f:
            rows = [
                r
                for r in csv.DictReader(f)
                if keep_below is None or int(r["iteration"]) < keep_below
            ]
    rows.append(row)
    fields = list(dict.fromkeys(k for r in rows for k in r))
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    os.replace(tmp, path)


def commit_folder(partial: Path) -> Path:
    """Rename ``iter_NNNN.partial`` to ``iter_NNNN`` (replacing a stale one)."""
    final = Path(str(partial).replace(".partial", ""))
    if final.exists():
        shutil.rmtree(final)
    os.replace(partial, final)
    return final


def now() -> float:
    """Wall clock for fps (monotonic)."""
    return time.perf_counter()
