"""Which cells of a table can be played: every column asked about every row before a job runs.

Some adversaries can only play against some protagonists: a white-box attack differentiates
the protagonist's networks, so a fixed controller (``--callable``) or a policy without a
critic cannot be its victim. An adversary spec says so through an optional method::

    def unplayable(self, game, agent, victims) -> str | None:
        '''Why this spec cannot play `agent` of `game` against `victims`, or None.'''

(`adversaries.whitebox` attacks have it). `not_applicable` asks it for every job of a table,
with the protagonists built once per scenario, so a table that mixes controllers and networks
is checked before anything is queued; `advgame.evaluation.evaluate` then plays the other cells
and records these as not applicable (`PayoffTable.not_applicable`, "n/a" in reports).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from typing import Any

from advgame.errors import ConfigError
from advgame.evaluation.table.jobs import EvalJob

__all__ = ["Rows", "learn_ahead", "not_applicable"]


def _asks(job: EvalJob) -> bool:
    """Whether any adversary spec of `job` can refuse a protagonist."""
    return any(callable(getattr(s, "unplayable", None)) for s in job.adversary_specs.values())


class Rows:
    """The games and protagonists a table's checks build, each once, shared by both checks.

    One game per scenario and its `make` arguments, one set of protagonist policies per row of
    it (a checkpoint is loaded once however many columns ask). `advgame.evaluation.evaluate`
    hands one to `learn_ahead` and then `not_applicable`; close it (or use ``with``) to close
    the games.
    """

    def __init__(self) -> None:
        self._games: dict[tuple[str, str], Any] = {}
        self._victims: dict[tuple[str, str, str], dict[str, Any]] = {}

    def game(self, job: EvalJob) -> Any:
        """The game of `job`'s column (made on first use)."""
        from advgame.core.registry import make

        key = _game_key(job)
        if key not in self._games:
            self._games[key] = make(job.scenario, **dict(job.make_kwargs))
        return self._games[key]

    def victims(self, job: EvalJob) -> dict[str, Any]:
        """`job`'s protagonist policies built for its game, as the evaluation builds them."""
        key = (*_game_key(job), job.protagonist)
        if key not in self._victims:
            self._victims[key] = _protagonists(self.game(job), job.protagonist_spec)
        return self._victims[key]

    def close(self) -> None:
        """Close every game made."""
        for game in self._games.values():
            game.close()
        self._games.clear()

    def __enter__(self) -> Rows:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _game_key(job: EvalJob) -> tuple[str, str]:
    """Which game `job`'s column plays: its scenario and `make` arguments."""
    return (job.scenario, repr(sorted(job.make_kwargs.items())))


def _given_or_own(rows: Rows | None) -> AbstractContextManager[Rows]:
    """`rows` left open for its owner, or a new `Rows` closed when the check ends."""
    return Rows() if rows is None else nullcontext(rows)


def not_applicable(jobs: Sequence[EvalJob], rows: Rows | None = None) -> dict[tuple[str, str], str]:
    """``{(protagonist, adversary): reason}`` for the jobs whose column cannot play their row.

    Each column's game is made once and each protagonist built once per scenario (a
    checkpoint is loaded once; with `rows`, the games and protagonists `learn_ahead` already
    built are reused); only jobs with an adversary spec that has ``unplayable`` are asked, so
    tables of noise and learned columns cost nothing here.
    """
    out: dict[tuple[str, str], str] = {}
    with _given_or_own(rows) as built:
        for job in (j for j in jobs if _asks(j)):
            reason = _reason(job, built.game(job), built.victims(job))
            if reason is not None:
                out[(job.protagonist, job.adversary)] = reason
    return out


def _protagonists(game: Any, spec: Any) -> dict[str, Any]:
    """The protagonist policies of `spec` built for `game` (as the evaluation builds them)."""
    from advgame.core.policy import as_policy

    specs = spec if isinstance(spec, Mapping) else dict.fromkeys(game.protagonists, spec)
    return {a: as_policy(specs[a], game.agent_info(a)) for a in game.protagonists if a in specs}


def _reason(job: EvalJob, game: Any, victims: Mapping[str, Any]) -> str | None:
    """The first adversary of `job` that refuses its protagonist, as a sentence, or None."""
    for agent, spec in job.adversary_specs.items():
        ask = getattr(spec, "unplayable", None)
        if not callable(ask):
            continue
        if agent not in game.adversaries:
            raise ConfigError(
                f"Column {job.adversary!r} gives a policy to {agent!r}, which is not an "
                f"adversary of its game; adversaries: {list(game.adversaries)}."
            )
        reason = ask(game, agent, victims)
        if reason is not None:
            return str(reason)
    return None


@dataclass(frozen=True)
class _Learn:
    """What one worker learns ahead of a table: `spec`'s per-protagonist model for one row."""

    scenario: str
    make_kwargs: Mapping[str, Any]
    protagonist_spec: Any
    agent: str
    spec: Any


def learn_ahead(
    jobs: Sequence[EvalJob],
    *,
    workers: int,
    executor: str,
    address: str | None = None,
    rows: Rows | None = None,
) -> int:
    """Train what columns learn per protagonist (PA-AD's directors) on the executor, in parallel.

    An adversary spec that learns something per victim says so through two optional methods,
    ``learned(game, agent, victims) -> bool`` and ``learn(game, agent, victims)`` (which
    trains it into a cache that attaching the spec reads; `advgame.adversaries.PAADAttack`
    has them). Attaching would learn it anyway, one row after another in this process
    (`not_applicable` attaches every column to every row); with more than one worker this
    learns every missing one first as executor units. `rows`: the games and protagonists to
    ask with (`not_applicable` reuses them). Returns how many were learned.
    """
    from advgame.runner.run import run_units

    if workers < 2 and executor == "local":
        return 0
    units: dict[tuple[str, ...], _Learn] = {}
    with _given_or_own(rows) as built:
        for job in jobs:
            for agent, spec in job.adversary_specs.items():
                if not (callable(getattr(spec, "learned", None)) and hasattr(spec, "learn")):
                    continue
                unit_id = (*_game_key(job), repr(job.protagonist_spec), agent, repr(spec))
                if unit_id in units:  # one unit per model
                    continue
                if not spec.learned(built.game(job), agent, built.victims(job)):
                    units[unit_id] = _Learn(
                        job.scenario, dict(job.make_kwargs), job.protagonist_spec, agent, spec
                    )
    if units:
        run_units(_learn, list(units.values()), executor=executor, workers=workers, address=address)
    return len(units)


def _learn(unit: _Learn) -> None:
    """A worker's unit of `learn_ahead`: build the row's game and victims, then learn."""
    import torch

    from advgame.core.registry import make

    torch.set_num_threads(1)
    game = make(unit.scenario, **dict(unit.make_kwargs))
    try:
        unit.spec.learn(game, unit.agent, _protagonists(game, unit.protagonist_spec))
    finally:
        game.close()
