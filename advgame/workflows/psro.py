"""PSRO-style population training: best responses and payoff entries as jobs, a meta-solver.

Each iteration reads as OpenSpiel's three named steps::

    update_agents()                # best responses, one job per side, trained in parallel:
                                   #   the protagonist vs the adversaries' meta-strategy,
                                   #   the adversary vs the protagonists' meta-strategy
    update_empirical_gamestate()   # the new payoff entries, one evaluation unit per cell and seed
    update_meta_strategies()       # uniform, fictitious play or Nash (LP) of the matrix

Iteration 0 seeds the game: the adversary population starts with its no-op (the nominal
game) and the first protagonist is a best response to it. The meta-game matrix holds each
protagonist's mean true return against each adversary (the protagonist maximizes).

Every job runs on `advgame.runner.run.run_units`, the local pool or Ray, with the same
code. A run directory survives a kill at any moment: finished best responses and payoff units
are part files (``jobs/``, ``payoff/parts/``) that are read back, never recomputed; members
(``population.json``, ``checkpoints/<member>/``) and the meta-game (``meta.json``) are
written atomically once an iteration's step is complete, with ``report.md`` (the meta-game
matrix and both meta-strategies of every iteration). `resume_psro` continues a run.
"""

from __future__ import annotations

import json
import logging
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from advgame.core.config import load_json, save_json, write_atomic
from advgame.core.fields import check_fields
from advgame.core.files import read_json, require
from advgame.errors import ConfigError
from advgame.reports.report import write_meta_report
from advgame.training.best_response import BestResponseJob, MixtureSpec, train_best_response
from advgame.training.population import Member, Population
from advgame.workflows.metasolver import game_value, solve

__all__ = ["PSROConfig", "load_meta", "resume_psro", "run_psro"]

log = logging.getLogger(__name__)
PROTAGONIST = "protagonist"
_META = {
    "protagonist": ("protagonists", "protagonist_strategy"),
    "adversary": ("adversaries", "adversary_strategy"),
}
"""A side's keys in a meta-game entry (``meta.json``): its members' ids and their strategy."""


@dataclass(frozen=True)
class PSROConfig:
    """A PSRO run; saved as ``config.json`` in its run directory."""

    scenario: str = "Hopper-v5"
    """Registered scenario id (one protagonist)."""
    preset: str = "rarl"
    """Preset giving the disruptors; its learned adversary is the adversary side."""
    adversary: str | None = None
    """The adversary agent trained (None: the preset's one adversary without a fixed policy)."""
    iterations: int = 3
    """PSRO iterations after the seeding iteration 0."""
    protagonist_steps: int = 2048
    """Steps of each protagonist best response."""
    adversary_steps: int = 2048
    """Steps of each adversary best response."""
    protagonist_algo: Literal["ppo", "sac", "td3", "recurrent-ppo", "ompo", "dbc", "rsc"] = "ppo"
    """Protagonist learner: SB3's, sb3-contrib's LSTM PPO, or one of the paper's off-policy robust
    baselines (OMPO, DBC, RSC; continuous actions only, refused before training otherwise)."""
    adversary_algo: Literal["ppo", "sac", "recurrent-ppo"] = "ppo"
    """Adversary learner (SB3, or sb3-contrib's LSTM PPO)."""
    protagonist_hparams: dict[str, Any] | None = None
    """Overrides of the protagonist learner config (e.g. {"n_steps": 512})."""
    adversary_hparams: dict[str, Any] | None = None
    """Overrides of the adversary learner config."""
    solver: Literal["uniform", "fictitious", "nash"] = "nash"
    """Meta-solver (`advgame.workflows.metasolver.SOLVERS`)."""
    eval_seeds: int = 2
    """Evaluation seeds per payoff entry (one job each)."""
    eval_episodes: int = 1
    """Episodes per seed."""
    max_episode_steps: int | None = None
    """Task time limit (None: the scenario's own)."""
    normalize: bool = True
    """Learners train behind VecNormalize."""
    seed: int = 0
    """Seeds every best response (plus its iteration) and the mixtures' draws."""

    def __post_init__(self) -> None:
        check_fields(self)
        for name in ("iterations", "protagonist_steps", "adversary_steps", "eval_seeds",
                     "eval_episodes"):  # fmt: skip
            value = getattr(self, name)
            least = 0 if name == "iterations" else 1
            if type(value) is not int or value < least:
                raise ConfigError(f"PSROConfig.{name} must be an int >= {least}, got {value!r}.")
        hints = typing.get_type_hints(PSROConfig)
        for name in ("protagonist_algo", "adversary_algo", "solver"):
            allowed = typing.get_args(hints[name])
            if getattr(self, name) not in allowed:
                raise ConfigError(
                    f"PSROConfig.{name} must be one of {allowed}, got {getattr(self, name)!r}."
                )
        steps = self.max_episode_steps
        if steps is not None and (type(steps) is not int or steps < 1):
            raise ConfigError(f"max_episode_steps must be None or an int >= 1, got {steps!r}.")

    def make_kwargs(self) -> dict[str, Any]:
        """`advgame.make` options of every game of the run."""
        extra = (
            {} if self.max_episode_steps is None else {"max_episode_steps": self.max_episode_steps}
        )
        return {"preset": self.preset, **extra}


@dataclass(frozen=True)
class _Executor:
    kind: str
    workers: int
    address: str | None
    max_retries: int

    def run(self, fn: Any, units: list[Any], parts: Path) -> list[Any]:
        from advgame.runner.run import run_units

        return run_units(fn, units, executor=self.kind, workers=self.workers,
                         address=self.address, max_retries=self.max_retries, parts_dir=parts)  # fmt: skip


def run_psro(
    config: PSROConfig,
    run_dir: str | Path,
    *,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    max_retries: int = 2,
    progress: bool = True,
) -> Path:
    """Start a PSRO run in `run_dir` (which must not hold one) and run it to the end.

    `progress`: a time-stamped line on stderr per finished iteration (its game value and the
    population's size, `advgame.core.progress.LineProgress`).
    """
    run_dir = Path(run_dir)
    if (run_dir / "config.json").exists():
        raise ConfigError(
            f"{run_dir} already holds a run; continue it with resume_psro({str(run_dir)!r})."
        )
    adversary = _adversary(config)
    run_dir.mkdir(parents=True, exist_ok=True)
    save_json(config, run_dir / "config.json")
    return _PSRO(
        config, run_dir, adversary, _Executor(executor, workers, address, max_retries), progress
    ).execute()


def resume_psro(
    run_dir: str | Path,
    *,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    max_retries: int = 2,
    progress: bool = True,
) -> Path:
    """Continue the PSRO run in `run_dir`: finished jobs are read back, not rerun.

    `progress`: as `run_psro`.
    """
    run_dir = Path(run_dir)
    if not (run_dir / "config.json").exists():
        raise ConfigError(f"No PSRO run in {run_dir} (no config.json); start one with run_psro.")
    config = load_json(PSROConfig, run_dir / "config.json")
    ex = _Executor(executor, workers, address, max_retries)
    return _PSRO(config, run_dir, _adversary(config), ex, progress).execute()


def load_meta(run_dir: str | Path) -> list[dict[str, Any]]:
    """The meta-game of every finished iteration (``meta.json``): matrix, strategies, value."""
    path = Path(run_dir) / "meta.json"
    if not path.exists():
        return []
    fix = f"Delete {path} and `advgame psro --run-dir {run_dir} --resume` rebuilds it."
    meta: list[dict[str, Any]] = read_json(path, "PSRO meta-game file", fix, kind=list)
    for entry in meta:
        require(entry, ("iteration", "solver", "value"), path, "PSRO meta-game file", fix)
    return meta


def _adversary(config: PSROConfig) -> str:
    from advgame.core.registry import make

    game = make(config.scenario, **config.make_kwargs())
    game.close()
    if len(game.protagonists) != 1:
        raise ConfigError(
            f"PSRO trains one protagonist; {config.scenario} has {game.protagonists}."
        )
    fixed = set(game.preset.adversaries) if game.preset is not None else set()
    free = [a for a in game.adversaries if a not in fixed]
    if config.adversary is not None:
        if config.adversary not in free:
            raise ConfigError(f"adversary={config.adversary!r} is not a learnable adversary of "
                              f"preset {config.preset!r}; expected one of {free}.")  # fmt: skip
        return config.adversary
    if len(free) != 1:
        raise ConfigError(f"Preset {config.preset!r} has learnable adversaries {free}; pick one "
                          "with adversary=..., or a preset with exactly one.")  # fmt: skip
    return free[0]


class _PSRO:
    """One run directory driven through its iterations."""

    def __init__(
        self, cfg: PSROConfig, run_dir: Path, adversary: str, ex: _Executor, progress: bool
    ) -> None:
        from advgame.core.progress import progress as display

        self.cfg, self.dir, self.adversary, self.ex = cfg, run_dir, adversary, ex
        self.pop_path = run_dir / "population.json"
        self.population = Population.load(self.pop_path) if self.pop_path.exists() else Population()
        self.meta = load_meta(run_dir)
        self.bar = display(cfg.iterations + 1, f"psro {run_dir.name}", unit="iteration",
                           initial=len(self.meta), show=progress, lines=True)  # fmt: skip
        if not self.population.of(adversary):
            self.population.add(Member.noop(adversary))

    def execute(self) -> Path:
        """Run every iteration not yet in ``meta.json``; return the run directory."""
        for it in range(len(self.meta), self.cfg.iterations + 1):
            self.update_agents(it)
            matrix = self.update_empirical_gamestate()
            self.update_meta_strategies(it, matrix)
        return self.dir

    # -- the three steps ----------------------------------------------------------------------
    def update_agents(self, it: int) -> None:
        """Train this iteration's best responses (as jobs) and add them to the population."""
        jobs = [self._job(PROTAGONIST, it)] + ([self._job(self.adversary, it)] if it else [])
        jobs = [j for j in jobs if not any(m.id == j.name for m in self.population)]
        records = self.ex.run(train_best_response, jobs, self.dir / "jobs")
        for job, rec in zip(jobs, records, strict=True):
            self._add_member(job, rec.value, it)
        self.population.save(self.pop_path)

    def update_empirical_gamestate(self) -> np.ndarray:
        """Evaluate every (protagonist, adversary) entry; finished entries are read back."""
        from advgame.evaluation import EvalJob, evaluate

        prots, advs = self._members()
        jobs = [
            EvalJob(scenario=self.cfg.scenario, make_kwargs=self.cfg.make_kwargs(),
                    protagonist=p.id, protagonist_spec=p.spec, adversary=a.id,
                    adversary_specs={self.adversary: a.spec}, seeds=tuple(range(self.cfg.eval_seeds)),
                    episodes=self.cfg.eval_episodes)
            for p in prots for a in advs
        ]  # fmt: skip
        table = evaluate(jobs, workers=self.ex.workers, progress=False, executor=self.ex.kind,
                         address=self.ex.address, max_retries=self.ex.max_retries,
                         results_dir=self.dir / "payoff")  # fmt: skip
        means: dict[tuple[str, str], list[float]] = {}
        for row in table.rows:
            means.setdefault((row["protagonist"], row["adversary"]), []).append(row["true_return"])
        return np.array([[float(np.mean(means[p.id, a.id])) for a in advs] for p in prots])

    def update_meta_strategies(self, it: int, matrix: np.ndarray) -> None:
        """Solve the meta-game; append the iteration's matrix and strategies to ``meta.json``."""
        row, col = solve(matrix, self.cfg.solver)
        prots, advs = self._members()
        entry = {
            "iteration": it,
            "protagonists": [m.id for m in prots],
            "adversaries": [m.id for m in advs],
            "matrix": matrix.tolist(),
            "protagonist_strategy": row.tolist(),
            "adversary_strategy": col.tolist(),
            "value": game_value(matrix, row, col),
            "solver": self.cfg.solver,
        }
        self.meta.append(entry)
        write_atomic(self.dir / "meta.json", json.dumps(self.meta, indent=2) + "\n")
        write_meta_report(self.dir, load_meta(self.dir))
        log.info("PSRO iteration %d: value %.3f", it, entry["value"])
        self.bar.set_postfix_str(
            f"iteration {it}: game value {entry['value']:,.1f}, "
            f"{len(prots)} protagonists x {len(advs)} adversaries",
            refresh=False,
        )
        self.bar.update()

    # -- helpers ----------------------------------------------------------------------------
    def _members(self) -> tuple[list[Member], list[Member]]:
        return self.population.of(PROTAGONIST), self.population.of(self.adversary)

    def _mixture(self, members: list[Member], weights: list[float], it: int) -> MixtureSpec:
        keep = [(m, w) for m, w in zip(members, weights, strict=True) if w > 1e-9]
        specs = tuple(m.opponent_spec() for m, _ in keep)
        total = sum(w for _, w in keep)
        return MixtureSpec(specs, tuple(w / total for _, w in keep), self.cfg.seed + it)

    def _job(self, side: str, it: int) -> BestResponseJob:
        """The best response of `side` at iteration `it`, against the last meta-strategy.

        Its opponents: the other side's members in the last meta-game, drawn by their
        meta-strategy (before the first meta-game, every member alike).
        """
        cfg = self.cfg
        last = self.meta[-1] if self.meta else None
        if side == PROTAGONIST:
            role, other_role, other = "protagonist", "adversary", self.adversary
        else:  # adversaries respond from iteration 1 on
            role, other_role, other = "adversary", "protagonist", PROTAGONIST
        ids, strategy = _META[other_role]
        members = self._listed(last[ids] if last else None, other)
        weights = last[strategy] if last else [1.0 / len(members)] * len(members)
        opponents = {other: self._mixture(members, weights, it)}
        algo, hparams, steps = (
            getattr(cfg, f"{role}_{key}") for key in ("algo", "hparams", "steps")
        )
        return BestResponseJob(name=f"{side}@{it}", scenario=cfg.scenario,
                               make_kwargs=cfg.make_kwargs(), agent=side, algo=algo,
                               hparams=hparams, opponents=opponents, steps=steps,
                               seed=cfg.seed + 1000 * it + (side != PROTAGONIST),
                               normalize=cfg.normalize)  # fmt: skip

    def _listed(self, ids: list[str] | None, agent: str) -> list[Member]:
        """The members of `agent` named in the last meta-game (all of them before the first)."""
        members = {m.id: m for m in self.population.of(agent)}
        return list(members.values()) if ids is None else [members[i] for i in ids]

    def _add_member(self, job: BestResponseJob, result: dict[str, Any], it: int) -> None:
        """Write a best response's files under ``checkpoints/<id>/``; add it as a member."""
        from advgame.agents.common.checkpoint import SB3Checkpoint

        folder = self.dir / "checkpoints" / job.name.replace("@", "_")
        folder.mkdir(parents=True, exist_ok=True)
        for name, blob in result["files"].items():
            path = folder / name
            # a run killed after writing a member but before saving the population writes
            # it again on resume: files already whole are left as they are (same bytes)
            if not (path.is_file() and path.read_bytes() == blob):
                write_atomic(path, blob)
        norm = str(folder / result["normalizer"]) if result["normalizer"] else None
        spec = SB3Checkpoint(str(folder / result["model"]), result["algo"], norm)
        side = "protagonist" if job.agent == PROTAGONIST else "adversary"
        self.population.add(Member(job.name, side, job.agent, spec, it, meta={"steps": job.steps}))
