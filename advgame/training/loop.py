"""Driving a `Trainer` through its iterations: building sides, committing, resuming, logging."""

from __future__ import annotations

import csv
import json
import logging
import os
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from advgame.agents.common.side import Side
from advgame.agents.common.stats import EpisodeStats
from advgame.core.config import write_atomic
from advgame.core.episodes import filler_action, rollout
from advgame.core.files import read_csv, read_json, reading, require
from advgame.core.policy import ConstantPolicy
from advgame.core.progress import progress
from advgame.core.registry import load, make
from advgame.core.views import view_factory
from advgame.errors import FileFormatError
from advgame.training.conditions import play_conditions, training_schedule
from advgame.training.config import PROTAGONISTS, learner_config
from advgame.training.population import ZERO, Member, Population
from advgame.training.trainer import Trainer

__all__ = ["Run"]

_TEAM_FACTORY = "advgame.core.team:team_factory"

log = logging.getLogger(__name__)


class Run:
    """Executes a trainer's iterations in its run directory, committing each one atomically."""

    def __init__(self, trainer: Trainer) -> None:
        self.t = trainer
        self.cfg = trainer.cfg
        self.dir = trainer.dir
        self.ckpt = self.dir / "checkpoints"
        self.prot_cfg = learner_config(self.cfg.protagonist_algo, self.cfg.protagonist_hparams)
        self.eval_games: dict[str, Any] = {}  # the in-training evaluation's, kept (conditions)
        self.adv_cfg = learner_config(self.cfg.adversary_algo, self.cfg.adversary_hparams)
        _warn_rollouts("protagonist", self.cfg.protagonist_steps, self.prot_cfg, self.cfg.n_envs)
        if self.t.learned:  # PPO-style runs train no adversary
            _warn_rollouts("adversary", self.cfg.adversary_steps, self.adv_cfg, self.cfg.n_envs)

    def execute(self, fresh: bool) -> Path:
        """Run every remaining iteration; return the run directory."""
        import torch

        torch.set_num_threads(1)
        start = self._fresh() if fresh else self._restore()
        cfg = self.cfg
        per_iter = cfg.protagonist_steps + cfg.adversary_steps * len(self.t.learned)
        total = per_iter * cfg.iterations + cfg.warmup_steps
        done = per_iter * (start - 1) + (cfg.warmup_steps if start > 1 else 0)
        show = self.t.progress
        bar = progress(
            total,
            f"train {cfg.scenario} {self.dir.name}",
            unit="step",
            initial=done,
            show=bool(show),
            lines=True if show == "lines" else None,
        )
        writer = _tensorboard(self.dir / "tb" / "loop")
        try:
            for it in range(start, cfg.iterations + 1):
                row = self._iteration(it, bar)
                bar.set_postfix_str(_summary(row, cfg.iterations))
                for key, value in row.items():
                    if (
                        key != "iteration"
                        and isinstance(value, (int, float))
                        and np.isfinite(value)
                    ):
                        if writer is not None:
                            writer.add_scalar(f"loop/{key}", value, it)
                log.info("iteration %d/%d: %s", it, cfg.iterations, row)
        finally:
            bar.close()
            if writer:
                writer.close()
            for opened in [*self.t.sides.values(), *self.eval_games.values()]:
                opened.close()
        return self.dir

    # -- one iteration ----------------------------------------------------------------------
    def _iteration(self, it: int, bar: Any) -> dict[str, Any]:
        t, cfg = self.t, self.cfg
        t.iteration = it
        partial = self.ckpt / f"iter_{it:04d}.partial"
        if partial.exists():
            shutil.rmtree(partial)
        prot_stats, adv_stats = EpisodeStats(bar), EpisodeStats(bar)
        start = now()
        if it == 1 and cfg.warmup_steps:
            self._warmup(prot_stats)
        t.update_protagonists(prot_stats)
        prot = t.sides[PROTAGONISTS]
        frozen = t.protagonist_specs(prot.save(partial, deterministic=False))
        t.update_adversaries(adv_stats, frozen)
        t.snapshot(partial)
        final = commit_folder(partial)
        evaluated = {
            a: _rebase(s, str(partial), str(final), deterministic=True) for a, s in frozen.items()
        }
        elapsed = now() - start
        p_ret, p_eps, _ = prot_stats.pop()
        a_ret, a_eps, clips = adv_stats.pop()
        steps = cfg.protagonist_steps + cfg.adversary_steps * len(t.learned)
        row: dict[str, Any] = {
            "iteration": it,
            "protagonist_steps": prot.steps,
            "adversary_steps": sum(t.sides[a].steps for a in t.learned),
            "protagonist_phase_true_return": p_ret,
            "protagonist_phase_episodes": p_eps,
            "protagonist_phase_true_cost": _mean(prot_stats.last_costs),
            "adversary_phase_true_return": a_ret,
            "adversary_phase_episodes": a_eps,
            "adversary_clipped": clips,
            "fps": steps / max(elapsed, 1e-9),
            "wall_s": elapsed,
            **self._quick_eval(evaluated, it),
        }
        t.population.save(self.dir / "population.json")
        append_progress(self.dir / "progress.csv", row, keep_below=it)
        write_state(
            self.dir,
            {
                "iteration": it,
                "rng": t.rng.bit_generator.state,
                "checkpoint": str(final.relative_to(self.dir)),
            },
        )
        drop_old_replays(self.ckpt, final)
        return row

    def _warmup(self, stats: EpisodeStats) -> None:
        prot = self.t.sides[PROTAGONISTS]
        prot.set_policies({a: load(ZERO)() for a in self.t.learned})
        prot.learn(self.cfg.warmup_steps, stats)

    def _quick_eval(self, protagonists: dict[str, Any], it: int) -> dict[str, float]:
        """Mean true return of the deterministic protagonists, nominal and attacked (full budget).

        With `TrainConfig.eval_conditions`, in each of those instead
        (`advgame.training.conditions`). Episode i plays episode ``1 + i`` of any scheduled adversary (a shift that varies per
        episode, `advgame.evaluation.schedule_index`'s convention), the same ones every
        iteration, so the attacked curve is comparable across iterations.
        """
        if not self.cfg.eval_episodes:
            return {}
        t = self.t
        if self.cfg.eval_conditions:  # the paper's protocol: named conditions instead
            where = training_schedule(t.sides[PROTAGONISTS])
            return play_conditions(t, protagonists, where, self.eval_games)
        game = make(self.cfg.scenario, **self.cfg.game_options(), phase="eval")
        seed = self.cfg.seed + 100_000 + it
        episodes = {"seed": seed, "episodes": self.cfg.eval_episodes, "first_index": 1}
        nominal = rollout(game, protagonists, **episodes)
        attackers = {
            **t.fixed,
            **{a: t.latest.get(a, t.population.of(a)[-1].spec) for a in t.learned},
        }
        attacked = rollout(game, {**protagonists, **attackers}, **episodes)
        game.close()
        return {
            "eval_nominal_return": _mean([r.true_return for r in nominal]),
            "eval_attacked_return": _mean([r.true_return for r in attacked]),
            "eval_nominal_cost": _mean([r.cost for r in nominal]),
            "eval_attacked_cost": _mean([r.cost for r in attacked]),
        }

    # -- building ---------------------------------------------------------------------------
    def _env_fns(self, agent: str, policies: dict[str, Any]) -> list[Any]:
        kwargs = {**self.t.train_kwargs, "phase": "train"}
        if agent == PROTAGONISTS and self.t.team:
            factory = load(_TEAM_FACTORY)
            return [factory(self.cfg.scenario, policies, **kwargs) for _ in range(self.cfg.n_envs)]
        if agent == PROTAGONISTS:
            agent = self.t.protagonists[0]
        return [
            view_factory(self.cfg.scenario, agent, policies, **kwargs)
            for _ in range(self.cfg.n_envs)
        ]

    def _build_sides(self, folder: Path | None) -> None:
        t, cfg = self.t, self.cfg
        game = make(cfg.scenario, **cfg.game_options())
        placeholders = {
            p: ConstantPolicy(filler_action(game.action_space(p))) for p in t.protagonists
        }
        game.close()
        run_steps = cfg.protagonist_steps * cfg.iterations + cfg.warmup_steps
        specs = [(PROTAGONISTS, self.prot_cfg, dict(t.fixed), run_steps)]
        for a in t.learned:
            others = {k: v for k, v in t.fixed.items() if k != a}
            specs.append(
                (a, self.adv_cfg, {**placeholders, **others}, cfg.adversary_steps * cfg.iterations)
            )
        tb = str(self.dir / "tb")
        for k, (agent, learner, policies, total) in enumerate(specs):
            fns = self._env_fns(agent, policies)
            if agent == PROTAGONISTS and t.team:
                t.sides[agent] = (
                    learner.make_learner(fns, cfg.seed + k, total, tb)
                    if folder is None
                    else _load_team(folder, learner, fns, tb)
                )
                continue
            agent_id = t.protagonists[0] if agent == PROTAGONISTS else agent
            if folder is None:
                t.sides[agent] = Side(
                    agent_id,
                    learner,
                    fns,
                    cfg.seed + k,
                    total,
                    normalize=cfg.normalize,
                    tensorboard_log=tb,
                    vec_env=cfg.vec_env,
                )
            else:
                t.sides[agent] = Side.load(
                    folder, agent_id, learner, fns, cfg.vec_env, tensorboard_log=tb
                )

    def _fresh(self) -> int:
        t = self.t
        self._build_sides(None)
        folder = self.ckpt / "iter_0000.partial"
        if folder.exists():
            shutil.rmtree(folder)
        for a in t.learned:
            t.population.add(Member.noop(a))
            spec = t.sides[a].save(folder)
            final = str(folder).replace(".partial", "")
            t.population.add(Member(f"{a}@0", "adversary", a, _rebase(spec, str(folder), final), 0))
        if folder.exists():
            commit_folder(folder)
        t.population.save(self.dir / "population.json")
        return 1

    def _restore(self) -> int:
        t = self.t
        state = read_state(self.dir)
        t.population = Population.load(self.dir / "population.json")
        t.population.members = [m for m in t.population if m.iteration <= state["iteration"]]
        with reading(self.dir / "state.json", "run state", RERUN.format(run=self.dir)):
            t.rng.bit_generator.state = state["rng"]
        folder = self.dir / state["checkpoint"]
        with reading(folder, "checkpoint folder", RERUN.format(run=self.dir)):
            self._build_sides(folder)
        log.info("resuming %s after iteration %d", self.dir, state["iteration"])
        return int(state["iteration"]) + 1


def _warn_rollouts(side: str, steps: int, learner: Any, n_envs: int) -> None:
    """Warn when a phase of `steps` is not whole on-policy rollouts (SB3 rounds each phase up)."""
    n = getattr(learner, "n_steps", None)
    if isinstance(n, int) and steps and steps % (n * n_envs):
        log.warning(
            "each %s phase asks for %d steps, but one rollout is n_envs x n_steps = %d x %d "
            "steps, so it trains %d: set n_steps to steps / n_envs (e.g. %s_hparams "
            '{"n_steps": %d})',
            side, steps, n_envs, n, -(-steps // (n * n_envs)) * n * n_envs, side,
            max(1, steps // n_envs),
        )  # fmt: skip


def _mean(values: list[float]) -> float:
    """The mean, or NaN for no values."""
    return float(np.mean(values)) if values else float("nan")


def _rebase(spec: Any, old: str, new: str, deterministic: bool | None = None) -> Any:
    """`spec` with file paths under `old` moved to `new` (and `deterministic` set, if given)."""
    from dataclasses import replace

    changes: dict[str, Any] = {"path": spec.path.replace(old, new)}
    if getattr(spec, "normalizer", None):
        changes["normalizer"] = spec.normalizer.replace(old, new)
    if deterministic is not None:
        changes["deterministic"] = deterministic
    return replace(spec, **changes)


def _load_team(folder: Path, learner: Any, fns: list[Any], tb: str) -> Any:
    """Rebuild a protagonist team learner saved in `folder` (resume)."""
    return learner.load_learner(folder, fns, tensorboard_log=tb)


def _summary(row: dict[str, Any], iterations: int) -> str:
    """An iteration's milestone for the progress display: its number and true returns."""
    text = f"iteration {row['iteration']}/{iterations} in {row['wall_s']:.0f} s"
    for key, name in (
        ("protagonist_phase_true_return", "protagonist return"),
        ("adversary_phase_true_return", "under the adversary"),
        ("eval_nominal_return", "evaluated nominal"),
        ("eval_attacked_return", "attacked"),
    ):
        value = row.get(key)
        if isinstance(value, float) and np.isfinite(value):
            text += f", {name} {value:,.0f}"
    return text


def _tensorboard(folder: Path) -> Any:
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:  # tensorboard is a dependency, but the loop must not die for a logger
        log.warning("tensorboard is not importable; loop scalars go to progress.csv only")
        return None
    return SummaryWriter(str(folder))


RERUN = (
    "Delete the run directory {run} and train it again, or restore its files from a backup "
    "(`advgame resume` continues only from intact ones)."
)
"""How to recover from a damaged run file (``{run}``: the run directory)."""


def write_state(run_dir: Path, state: dict[str, Any]) -> None:
    """Write ``state.json`` atomically."""
    write_atomic(run_dir / "state.json", json.dumps(state, indent=2) + "\n")


def read_state(run_dir: Path) -> dict[str, Any]:
    """Read ``state.json``: the last finished iteration, the rng state and its checkpoint.

    Raises:
        FileFormatError: it is empty, truncated, or lacks a field (another version).

    """
    path, fix = run_dir / "state.json", RERUN.format(run=run_dir)
    state = read_json(path, "run state", fix, kind=dict)
    require(state, ("iteration", "rng", "checkpoint"), path, "run state", fix)
    types = {"iteration": int, "rng": dict, "checkpoint": str}
    bad = [k for k, kind in types.items() if not isinstance(state[k], kind)]
    if bad:
        raise FileFormatError(
            f"The run state {path} has {bad} of the wrong type: written by another version or "
            f"edited by hand. {fix}",
            path=str(path),
        )
    return state


def append_progress(path: Path, row: dict[str, Any], keep_below: int | None = None) -> None:
    """Append a row to the progress CSV; on resume drop rows of iterations >= `keep_below`."""
    rows: list[dict[str, Any]] = []
    if path.exists():
        fix = RERUN.format(run=path.parent)
        with reading(path, "progress file", fix):
            rows = [
                r
                for r in read_csv(path, "progress file", fix, columns=("iteration",))
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


def drop_old_replays(ckpt: Path, keep: Path) -> None:
    """Delete replay buffers of checkpoints before `keep`: only a resume reads one, from the latest.

    An off-policy learner's buffer is SB3's preallocated arrays (200 MB for Hopper's 1M
    transitions), so keeping one per iteration would fill the disk; the policies stay.
    """
    for path in ckpt.glob("iter_*/*_replay.pkl"):
        if path.parent != keep:
            path.unlink(missing_ok=True)


def now() -> float:
    """Wall clock for fps (monotonic)."""
    return time.perf_counter()
