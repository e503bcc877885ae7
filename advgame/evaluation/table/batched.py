"""Batched evaluation: the episodes of many `EvalJob`s played in lockstep (what `run_job` runs).

A job's episodes (every seed, every episode of a seed) are independent games, and so are the
episodes of different jobs, so they are played side by side: one game per episode, each with
its own freshly built policies, stepped move by move together
(`advgame.core.episodes.rollout_batch`), and before each move the policies of one agent that
share a ``batch_key`` are asked for all their games at once: one torch forward pass for the
copies of a frozen SB3 network (a protagonist against every column of a table, a learned
adversary against every protagonist) instead of one per episode. Every episode is the one the
per-episode path (`play_job_sequential`, today's `rollout` per seed) plays with the same seed,
so the rows are identical (``tests/test_batched_eval.py`` checks them value for value). Both
paths tell every episode which episode of a per-episode schedule it plays
(`advgame.evaluation.table.jobs.schedule_index`), so a sinusoidal shift moves from seed to seed
and from episode to episode even though each episode's policies are fresh.
`play_jobs` plays a group of jobs (`advgame.evaluation.evaluate` hands it groups of up to
`LOCKSTEP_EPISODES` episodes in this process); `play_job` is the group of one.

Two kinds of jobs keep the per-episode path, because their episodes are not independent of
each other: a game whose disruptor shift persists across episodes (``Schedule.persist``), and a
policy that samples from a generator shared across episodes (a non-deterministic SB3 policy
draws from torch's global generator).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

from advgame.core.episodes import EpisodeResult, build_policies, rollout, rollout_batch
from advgame.errors import ConfigError
from advgame.evaluation.table.jobs import SEED_STRIDE, EvalJob, schedule_index

__all__ = ["LOCKSTEP_EPISODES", "play_job", "play_job_sequential", "play_jobs"]

LOCKSTEP_EPISODES = 128
"""At most this many episodes (games) are played side by side by one `play_jobs` call of
`advgame.evaluation.evaluate` (`advgame.evaluation.table.jobs.lockstep_groups`)."""


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
    from advgame.core.registry import make

    game = make(job.scenario, **job.make_kwargs)
    try:
        specs, results = _specs(job, game.protagonists), []
        for seed in job.seeds:
            policies = _policies(job, game, specs)
            first = schedule_index(seed, 0, job.episodes)
            played = rollout(
                game, policies, seed=seed * SEED_STRIDE, episodes=job.episodes, first_index=first
            )
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
    return play_jobs([job])[0]


def play_jobs(jobs: Sequence[EvalJob]) -> list[list[dict[str, Any]]]:
    """Play every episode of every job in lockstep; each job's rows, as `play_job_sequential`'s.

    One game per episode across all `jobs`, so before each move the policies of one agent that
    share a ``batch_key`` (the copies of one frozen network, whatever the job) are asked once
    for all their games. A job whose episodes are not independent (see the module docstring)
    is played alone, by the per-episode path.
    """
    plans: list[tuple[list[tuple[int, int]], list[Any], list[Any]] | None] = []
    try:
        for job in jobs:
            plans.append(_plan(job))
        batch = [(job.episodes, p) for job, p in zip(jobs, plans, strict=True) if p is not None]
        results = rollout_batch(
            [g for _, (_, games, _) in batch for g in games],
            [pol for _, (_, _, pols) in batch for pol in pols],
            [s * SEED_STRIDE + i for _, (eps, _, _) in batch for s, i in eps],
            [schedule_index(s, i, n) for n, (eps, _, _) in batch for s, i in eps],
        )
    except BaseException:
        _close([g for p in plans if p is not None for g in p[1]])
        raise
    out, at = [], 0
    for job, plan in zip(jobs, plans, strict=True):
        if plan is None:
            out.append(play_job_sequential(job))
            continue
        episodes, games, _ = plan
        mine, at = results[at : at + len(episodes)], at + len(episodes)
        _POOL.give(job, games)
        out.append(_rows(job, [(s, i, r) for (s, i), r in zip(episodes, mine, strict=True)]))
    return out


def _plan(job: EvalJob) -> tuple[list[tuple[int, int]], list[Any], list[Any]] | None:
    """`job`'s episodes, games and built policies; None if it must be played alone."""
    episodes = [(seed, i) for seed in job.seeds for i in range(job.episodes)]
    games = _POOL.take(job, len(episodes))
    try:
        specs = _specs(job, games[0].protagonists)
        policies = [_policies(job, game, specs) for game in games]
    except BaseException:
        _close(games)
        raise
    if not _independent(games[0], policies[0]):  # alone, even with one episode: a sampling
        _close(games)  # policy's draws would interleave with other jobs' in a group
        return None
    return episodes, games, policies


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
    """Scenarios and option sets kept at most."""
    PER_KEY = 2 * LOCKSTEP_EPISODES
    """Games kept per scenario and option set at most."""

    def __init__(self) -> None:
        self._free: dict[str, list[Any]] = {}

    @staticmethod
    def _key(job: EvalJob) -> str:
        return f"{job.scenario}|{sorted(job.make_kwargs.items())!r}"

    def take(self, job: EvalJob, n: int) -> list[Any]:
        """`n` games of `job`'s scenario and options, kept ones first."""
        from advgame.core.registry import make

        free = self._free.get(self._key(job), [])
        games = [free.pop() for _ in range(min(n, len(free)))]
        while len(games) < n:
            games.append(make(job.scenario, **job.make_kwargs))
        return games

    def give(self, job: EvalJob, games: list[Any]) -> None:
        """Keep `games` for later jobs (or close them: scaled budgets, too many keys)."""
        key = self._key(job)
        if games[0].scaled_targets or (len(self._free) >= self.KEYS and key not in self._free):
            _close(games)
            return
        free = self._free.setdefault(key, [])
        room = max(0, self.PER_KEY - len(free))
        free.extend(games[:room])
        _close(games[room:])


_POOL = _GamePool()
