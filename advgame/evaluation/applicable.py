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
from typing import Any

from advgame.errors import ConfigError
from advgame.evaluation.jobs import EvalJob

__all__ = ["not_applicable"]


def _asks(job: EvalJob) -> bool:
    """Whether any adversary spec of `job` can refuse a protagonist."""
    return any(callable(getattr(s, "unplayable", None)) for s in job.adversary_specs.values())


def not_applicable(jobs: Sequence[EvalJob]) -> dict[tuple[str, str], str]:
    """``{(protagonist, adversary): reason}`` for the jobs whose column cannot play their row.

    Each column's game is made once and each protagonist built once per scenario (a
    checkpoint is loaded once); only jobs with an adversary spec that has ``unplayable`` are
    asked, so tables of noise and learned columns cost nothing here.
    """
    from advgame.core.registry import make

    asked = [j for j in jobs if _asks(j)]
    games: dict[tuple[str, str], Any] = {}
    victims: dict[tuple[str, str], dict[str, Any]] = {}
    out: dict[tuple[str, str], str] = {}
    try:
        for job in asked:
            key = (job.scenario, repr(sorted(job.make_kwargs.items())))
            if key not in games:
                games[key] = make(job.scenario, **dict(job.make_kwargs))
            game = games[key]
            row = (job.scenario, job.protagonist)
            if row not in victims:
                victims[row] = _protagonists(game, job.protagonist_spec)
            reason = _reason(job, game, victims[row])
            if reason is not None:
                out[(job.protagonist, job.adversary)] = reason
    finally:
        for game in games.values():
            game.close()
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
