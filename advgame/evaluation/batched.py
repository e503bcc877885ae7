"""Batched evaluation: all episodes of one `EvalJob` played in lockstep (what `run_job` runs).

A job's episodes (every seed, every episode of a seed) are independent games, so they are
played side by side: one game per episode, each with its own freshly built policies, stepped
move by move together (`advgame.core.episodes.rollout_batch`), and before each move the
policies of one agent are asked for all games at once, one torch forward pass for the copies of
a frozen SB3 network instead of one per episode. Every episode is the one the per-episode path
(`play_job_sequential`, today's `rollout` per seed) plays with the same seed, so the rows are
identical (``tests/test_vector.py`` checks them value for value).

Two kinds of jobs keep the per-episode path, because their episodes are not independent of
each other: a game whose disruptor shift persists across episodes (``Schedule.persist``), and a
policy that samples from a generator shared across episodes (a non-deterministic SB3 policy
draws from torch's global generator).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from advgame.core.episodes import EpisodeResult, build_policies, rollout, rollout_batch
from advgame.errors import ConfigError
from advgame.evaluation.jobs import SEED_STRIDE, EvalJob

__all__ = ["play_job", "play_job_sequential"]


def _specs(job: EvalJob, protagonists: tuple[str, ...]) -> dict[str, Any]:
    prot = job.protagonist_spec
    specs = {**(prot if isinstance(prot, Mapping) else dict.fromkeys(protagonists, prot))}
    specs.update(job.adversary_specs)
    return specs


def _policies(job: EvalJob, game: Any, specs: Mapping[str, Any]) -> dict[str, Any]:
    try:
        return build_policies(game, specs)
    except ConfigError as exc:
        where = f"{job.scenario} made with {job.make_kwargs}"
        msg = f"Job {job.protagonist!r} vs {job.adversary!r} on {where}: {exc}"
        raise type(exc)(msg) from None


def _rows(job: EvalJob, results: list[tuple[int, int, EpisodeResult]]) -> list[dict[str, Any]]:
    head = {"scenario": job.scenario, "protagonist": job.protagonist, "adversary": job.adversary}
    rows = []
    for seed, i, r in results:
        res = {**dataclasses.asdict(r), "clipped": int(sum(r.clipped.values()))}
        rows.append({**head, "seed": seed, "episode": i, **res, **job.tags})
    return rows


def play_job_sequential(job: EvalJob) -> list[dict[str, Any]]:
    """The per-episode path: one game, policies built afresh per seed, episodes one by one."""
    import advgame

    game = advgame.make(job.scenario, **job.make_kwargs)
    try:
        specs, results = _specs(job, game.protagonists), []
        for seed in job.seeds:
            policies = _policies(job, game, specs)
            played = rollout(game, policies, seed=seed * SEED_STRIDE, episodes=job.episodes)
            results += [(seed, i, r) for i, r in enumerate(played)]
    finally:
        game.close()
    return _rows(job, results)


def _independent(game: Any, policies: Mapping[str, Any]) -> bool:
    """Whether this job's episodes may run side by side (see the module docstring)."""
    if any(d.schedule.persist for d in game.disruptors.values()):
        return False
    return all(getattr(p, "deterministic", True) is not False for p in policies.values())


def play_job(job: EvalJob) -> list[dict[str, Any]]:
    """Play all episodes of `job` in lockstep; the rows `play_job_sequential` returns.

    Rows come seed by seed, episode by episode, one per episode (`COLUMNS` and the job's tags).
    """
    episodes = [(seed, i) for seed in job.seeds for i in range(job.episodes)]
    games = _POOL.take(job, len(episodes))
    try:
        specs = _specs(job, games[0].protagonists)
        policies = [_policies(job, game, specs) for game in games]
        if len(episodes) > 1 and not _independent(games[0], policies[0]):
            _close(games)
            return play_job_sequential(job)
        seeds = [seed * SEED_STRIDE + i for seed, i in episodes]
        results = rollout_batch(games, policies, seeds)
    except BaseException:
        _close(games)
        raise
    _POOL.give(job, games)
    return _rows(job, [(s, i, r) for (s, i), r in zip(episodes, results, strict=True)])


def _close(games: list[Any]) -> None:
    for game in games:
        game.close()


class _GamePool:
    """Games kept between jobs of this process, per scenario and `make` options.

    A job needs one game per episode; making them is a good part of a short job's time, and
    games are reusable by design: `Game.reset(seed)` restores every nominal parameter and
    reseeds everything (invariants 4 and 5). Games with a normalized-space observation budget
    are not kept: their scale is set by the protagonist of the job that played them.
    """

    KEYS = 8

    def __init__(self) -> None:
        self._free: dict[str, list[Any]] = {}

    @staticmethod
    def _key(job: EvalJob) -> str:
        return f"{job.scenario}|{sorted(job.make_kwargs.items())!r}"

    def take(self, job: EvalJob, n: int) -> list[Any]:
        """`n` games of `job`'s scenario and options, kept ones first."""
        import advgame

        free = self._free.pop(self._key(job), [])
        games = free[:n]
        _close(free[n:])
        while len(games) < n:
            games.append(advgame.make(job.scenario, **job.make_kwargs))
        return games

    def give(self, job: EvalJob, games: list[Any]) -> None:
        """Keep `games` for later jobs (or close them: scaled budgets, too many keys)."""
        scaled = any(
            getattr(d.spec, "space", "raw") == "normalized" for d in games[0].disruptors.values()
        )
        if scaled or (len(self._free) >= self.KEYS and self._key(job) not in self._free):
            _close(games)
            return
        self._free[self._key(job)] = games


_POOL = _GamePool()
