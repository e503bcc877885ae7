"""Evaluation jobs: one `EvalJob` per payoff-matrix cell, and builders of whole populations.

An `EvalJob` is a pure, picklable value (a protagonist against one adversary set-up over some
seeds); `advgame.evaluation.evaluate` plays a list of them. `AdversarySetup` names one column;
`population_jobs` crosses protagonists with set-ups, `budget_sweep` builds a "return vs budget"
curve, `shift_grid` a grid over a preset's dynamics intervals.
"""

from __future__ import annotations

import itertools
import math
import operator
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, cast

import numpy as np

from advgame.core.fields import check_fields
from advgame.errors import ConfigError, UnknownNameError, did_you_mean
from advgame.evaluation.table.payoff import COLUMNS, NOMINAL

__all__ = [
    "SEED_STRIDE",
    "AdversarySetup",
    "EvalJob",
    "budget_sweep",
    "lockstep_groups",
    "population_jobs",
    "schedule_index",
    "shift_grid",
    "split_seeds",
    "unit_size",
]

SEED_STRIDE = 10_000
"""Episode ``i`` of evaluation seed ``s`` plays `rollout` seed ``s * SEED_STRIDE + i``, so the
episodes of seeds 0, 1, 2, ... never share a reset seed (as ``s + i`` would)."""


def schedule_index(seed: int, episode: int, episodes: int) -> int:
    """The episode of a per-episode schedule that episode `episode` of evaluation seed `seed` plays.

    A job's episodes are numbered seed by seed, ``k = seed * episodes + episode`` (`episodes`
    per seed), and episode ``k`` plays schedule index ``i = k + 1``: seed 0's first episode is
    OMPO's first training episode (its loop counts from 1), and no evaluation episode plays
    ``i = 0``, where a sinusoid sits at its centre (the nominal body for Hopper's and
    Walker2d's ``shift-sinusoid``). The index depends on nothing but the job, so units of
    seeds, lockstep groups and workers play the same schedule (`split_seeds` keeps
    `EvalJob.episodes`). Scheduled policies receive it through ``set_episode_index``
    (`advgame.core.episodes.reseed_policies`); other policies ignore it.

    Example:
        >>> [schedule_index(s, 0, 1) for s in range(4)], schedule_index(2, 1, 8)
        ([1, 2, 3, 4], 18)

    """
    return seed * episodes + episode + 1


def _check_spec(spec: Any, what: str) -> None:
    if not (hasattr(spec, "build") or hasattr(spec, "act") or callable(spec)):
        msg = "expected a PolicySpec (build), a Policy (reset/act) or a callable obs -> action"
        raise ConfigError(f"{what} is {spec!r}; {msg}.")


def _seeds(seeds: Any, episodes: int) -> tuple[int, ...]:
    try:
        scalar = isinstance(seeds, (int, np.integer)) and not isinstance(seeds, bool)
        out = tuple(operator.index(s) for s in ((seeds,) if scalar else seeds))
    except (TypeError, ValueError):
        raise ConfigError(f"seeds must be ints, got {seeds!r}; e.g. seeds=(0, 1, 2).") from None
    if not out or min(out) < 0 or len(set(out)) != len(out):
        raise ConfigError(f"seeds must be distinct ints >= 0, got {seeds!r}; e.g. (0, 1, 2).")
    if episodes > SEED_STRIDE:
        raise ConfigError(f"episodes={episodes} > {SEED_STRIDE} per seed; use more seeds.")
    return out


@dataclass(frozen=True, kw_only=True)
class EvalJob:
    """One payoff-matrix cell: a protagonist against one adversary set-up, over seeds.

    A pure value whose every part pickles (specs, module-level functions), so it can run in a
    worker process or a Ray task. Unknown scenarios and malformed fields fail on construction.
    """

    scenario: str
    """Registered scenario id, e.g. ``"Hopper-v5"``."""
    make_kwargs: Mapping[str, Any] = field(default_factory=dict)
    """`advgame.make` options (``preset=`` or ``disruptors=``, task options); ``phase`` defaults
    to ``"eval"``."""
    protagonist: str
    """The protagonist's name (a row of the matrix)."""
    protagonist_spec: Any
    """A `PolicySpec`, a `Policy` or a picklable module-level callable ``obs -> action`` played
    by every protagonist of the game, or a dict ``{protagonist agent id: spec}``."""
    adversary: str = NOMINAL
    """The adversary set-up's name (a column of the matrix)."""
    adversary_specs: Mapping[str, Any] = field(default_factory=dict)
    """``{adversary agent id: spec}``; adversaries not listed play their no-op."""
    seeds: tuple[int, ...] = (0,)
    """Distinct seeds; episode ``i`` of seed ``s`` resets with ``s * SEED_STRIDE + i`` and is
    episode ``s * episodes + i + 1`` of a per-episode schedule (`schedule_index`)."""
    episodes: int = 1
    """Episodes per seed."""
    tags: Mapping[str, Any] = field(default_factory=dict)
    """Extra scalar columns copied into every row (e.g. ``{"budget": 0.1}``)."""

    def __post_init__(self) -> None:
        from advgame.core.registry import scenario_spec

        check_fields(self, skip=("seeds",))  # seeds may also be a count; _seeds checks them
        scenario_spec(self.scenario)  # an unknown id fails here, with a "did you mean"
        for name in ("protagonist", "adversary"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value:
                raise ConfigError(f"EvalJob.{name} must be a non-empty str, got {value!r}.")
        if type(self.episodes) is not int or self.episodes < 1:
            raise ConfigError(f"EvalJob.episodes must be an int >= 1, got {self.episodes!r}.")
        object.__setattr__(self, "seeds", _seeds(self.seeds, self.episodes))
        for name in ("make_kwargs", "adversary_specs", "tags"):
            if not isinstance(getattr(self, name), Mapping):
                raise ConfigError(f"EvalJob.{name} must be a dict, got {getattr(self, name)!r}.")
        object.__setattr__(self, "make_kwargs", {"phase": "eval", **self.make_kwargs})
        if self.make_kwargs["phase"] not in ("train", "eval"):
            raise ConfigError(f"phase must be 'train' or 'eval': {self.make_kwargs['phase']!r}.")
        if "preset" in self.make_kwargs and "disruptors" in self.make_kwargs:
            raise ConfigError("make_kwargs has both preset= and disruptors=; give one of them.")
        prot = self.protagonist_spec
        for agent, spec in prot.items() if isinstance(prot, Mapping) else [("all", prot)]:
            _check_spec(spec, f"The protagonist_spec ({agent})")
        for agent, spec in self.adversary_specs.items():
            _check_spec(spec, f"The adversary spec of {agent!r}")
        bad = {k: v for k, v in self.tags.items() if k in COLUMNS or not np.isscalar(v)}
        if bad:
            raise ConfigError(f"tags {bad} must be scalars named apart from the columns {COLUMNS}.")


def split_seeds(jobs: Sequence[EvalJob], per_unit: int = 1) -> list[EvalJob]:
    """Return the jobs cut into units of at most `per_unit` seeds each: what workers run.

    `run_job` builds policies afresh for every seed, so the rows of the units are the rows of
    the whole jobs, in the same order; finer units balance the workers and make each finished
    unit a result that a restart keeps, while a unit's episodes are played in lockstep
    (batched policy calls, `advgame.evaluation.table.batched`).

    Example:
        >>> job = EvalJob(scenario="Hopper-v5", protagonist="zero", protagonist_spec=abs,
        ...               seeds=(0, 1, 2))
        >>> [u.seeds for u in split_seeds([job])]
        [(0,), (1,), (2,)]
        >>> [u.seeds for u in split_seeds([job], per_unit=2)]
        [(0, 1), (2,)]

    """
    if type(per_unit) is not int or per_unit < 1:
        raise ConfigError(f"per_unit must be an int >= 1, got {per_unit!r}.")
    return [
        replace(j, seeds=tuple(j.seeds[i : i + per_unit]))
        for j in jobs
        for i in range(0, len(j.seeds), per_unit)
    ]


def unit_size(jobs: Sequence[EvalJob], workers: int, executor: str = "local") -> int:
    """Seeds per unit for `workers`: whole jobs in this process, else >= 3 units per worker.

    Playing in this process (local, one worker) keeps every job whole, so all its episodes
    run in lockstep; a pool or Ray gets units of as many seeds as still leave at least three
    units per worker (one seed each when there are fewer), so W workers stay busy to the end.

    Example:
        >>> job = EvalJob(scenario="Hopper-v5", protagonist="zero", protagonist_spec=abs,
        ...               seeds=tuple(range(12)))
        >>> unit_size([job], workers=1), unit_size([job], workers=2), unit_size([job], 8)
        (12, 2, 1)

    """
    longest = max((len(j.seeds) for j in jobs), default=1)
    if executor == "local" and workers == 1:
        return longest
    total = sum(len(j.seeds) for j in jobs)
    return max(1, min(longest, total // (3 * workers)))


def lockstep_groups(jobs: Sequence[EvalJob], episodes: int = 128) -> list[tuple[EvalJob, ...]]:
    """Return consecutive jobs grouped by up to `episodes` episodes: what one process plays at once.

    Each group is played in lockstep (`advgame.evaluation.table.batched.play_jobs`), so a frozen
    network is asked once per move for every game of the group that it plays; a job with more
    episodes than `episodes` is a group of its own. The groups, flattened, are `jobs`.

    Example:
        >>> job = EvalJob(scenario="Hopper-v5", protagonist="zero", protagonist_spec=abs,
        ...               seeds=(0, 1, 2))
        >>> [len(g) for g in lockstep_groups([job] * 5, episodes=6)]
        [2, 2, 1]

    """
    if type(episodes) is not int or episodes < 1:
        raise ConfigError(f"episodes must be an int >= 1, got {episodes!r}.")
    groups: list[tuple[EvalJob, ...]] = []
    group: list[EvalJob] = []
    size = 0
    for job in jobs:
        n = len(job.seeds) * job.episodes
        if group and size + n > episodes:
            groups.append(tuple(group))
            group, size = [], 0
        group.append(job)
        size += n
    if group:
        groups.append(tuple(group))
    return groups


# -- building populations of jobs -----------------------------------------------------------
@dataclass(frozen=True)
class AdversarySetup:
    """One adversary column of a payoff matrix: how its game is made and who plays whom."""

    make_kwargs: Mapping[str, Any] = field(default_factory=dict)
    """`advgame.make` options (``preset=``/``disruptors=``); see `EvalJob.make_kwargs`."""
    specs: Mapping[str, Any] = field(default_factory=dict)
    """``{adversary agent id: spec}``; see `EvalJob.adversary_specs`."""
    tags: Mapping[str, Any] = field(default_factory=dict)
    """Extra row columns; see `EvalJob.tags`."""

    @classmethod
    def nominal(cls) -> AdversarySetup:
        """Return the undisrupted game (no adversary agents at all)."""
        return cls({"disruptors": {}})

    @classmethod
    def from_preset(cls, scenario: str, preset: str) -> AdversarySetup:
        """Return a preset played by its suggested adversaries (`Preset.adversaries`)."""
        from advgame.core.registry import scenario_spec

        presets = scenario_spec(scenario).load_presets()
        if preset not in presets:
            hint = did_you_mean(preset, presets)
            msg = f"Scenario {scenario!r} has no preset {preset!r}.{hint} Presets: {list(presets)}"
            raise UnknownNameError(msg)
        return cls({"preset": preset}, dict(presets[preset].adversaries))


def population_jobs(
    scenario: str,
    protagonists: Mapping[str, Any],
    adversaries: Mapping[str, AdversarySetup],
    *,
    seeds: Sequence[int] = (0,),
    episodes: int = 1,
) -> list[EvalJob]:
    """Return one `EvalJob` per (protagonist, adversary) pair: the whole payoff matrix.

    `protagonists` maps names to specs (`EvalJob.protagonist_spec`), `adversaries` names to
    `AdversarySetup`s (name one `NOMINAL` for the degradation metrics); `seeds` and `episodes`
    are those of every job.
    """
    bad = [n for n, s in adversaries.items() if not isinstance(s, AdversarySetup)]
    if bad:
        example = "AdversarySetup.from_preset(scenario, 'state-gauss-0.1')"
        raise ConfigError(f"adversaries {bad} must be AdversarySetup values, e.g. {example}.")
    return [
        EvalJob(scenario=scenario, make_kwargs=s.make_kwargs, protagonist=p, protagonist_spec=spec,
                adversary=a, adversary_specs=s.specs, seeds=tuple(seeds), episodes=episodes,
                tags=s.tags)
        for p, spec in protagonists.items()
        for a, s in adversaries.items()
    ]  # fmt: skip


def _gaussian(budget: float) -> Any:
    from advgame.adversaries import GaussianAdversary

    return GaussianAdversary(std=budget)


def budget_sweep(
    scenario: str,
    protagonists: Mapping[str, Any],
    budgets: Sequence[float],
    *,
    kind: str = "observation",
    seeds: Sequence[int] = (0,),
    episodes: int = 1,
    adversary: Callable[[float], Any] = _gaussian,
    make_kwargs: Mapping[str, Any] | None = None,
) -> list[EvalJob]:
    """Return jobs for a "return vs budget" curve: each protagonist against each budget.

    Budget ``b`` is the column ``f"{kind}-{b:g}"`` with row tag ``budget=b``: an unbounded
    `kind` disruptor (the paper's random mode) played by ``adversary(b)``, by default
    ``GaussianAdversary(std=b)``. `make_kwargs` adds task options (``max_episode_steps``).

    Example:
        >>> jobs = budget_sweep("Hopper-v5", {"zero": abs}, [0.0, 0.05, 0.1, 0.15])
        >>> [(j.adversary, j.tags["budget"]) for j in jobs][:2]
        [('observation-0', 0.0), ('observation-0.05', 0.05)]

    """
    if kind not in ("observation", "action", "reward"):
        raise ConfigError(f"budget_sweep perturbs observation, action or reward; got {kind!r}.")
    if not budgets or any(not math.isfinite(b) or b < 0 for b in budgets):
        raise ConfigError(f"budgets must be finite and >= 0, got {budgets!r}; e.g. [0, 0.1].")
    kw = {**(make_kwargs or {}), "disruptors": {kind: {"bounded": False}}}
    agent = f"{kind}_adversary"
    setups = {
        f"{kind}-{b:g}": AdversarySetup(kw, {agent: adversary(float(b))}, {"budget": float(b)})
        for b in budgets
    }
    return population_jobs(scenario, protagonists, setups, seeds=seeds, episodes=episodes)


def shift_grid(scenario: str, preset: str, points: int = 3) -> Iterator[tuple[str, dict]]:
    """Return a grid over a preset's dynamics intervals: ``(name, {agent: ConstantAdversary})``.

    Each parameter takes `points` evenly spaced values from its interval's low to its high end,
    both included; the grid, built lazily, is the product over all parameters of all dynamics
    adversaries. Play an entry with ``AdversarySetup({"preset": preset}, specs)``.

    Example:
        >>> [n for n, _ in shift_grid("Ant-v5", "shift-uniform", points=2)][:2]
        ['gravity=9.81,wind=0.8', 'gravity=9.81,wind=1.2']

    """
    from advgame.core.registry import make
    from advgame.disruptors import DynamicsDisruptor
    from advgame.disruptors.dynamics import DynamicsRuntime

    if type(points) is not int or points < 2:
        raise ConfigError(f"points must be an int >= 2 (both interval ends), got {points!r}.")
    game = make(scenario, preset=preset)
    game.close()
    dyn = {a: d for a, d in game.disruptors.items() if isinstance(d, DynamicsRuntime)}
    if not dyn:
        raise ConfigError(
            f"Preset {preset!r} of {scenario!r} has no dynamics disruptor (adversaries: "
            f"{list(game.adversaries)}); use a shift preset, e.g. preset='shift-uniform'."
        )
    axes, labels = [], []
    for agent, d in dyn.items():
        params = cast(DynamicsDisruptor, d.spec).params
        for p, lo, hi in zip(params, d.low, d.high, strict=True):
            axes.append([(agent, float(v)) for v in dict.fromkeys(np.linspace(lo, hi, points))])
            where = f"[{','.join(p.names)}]" if p.names else ""
            labels.append(f"{agent}." * (len(dyn) > 1) + p.kind + where)
    return _grid(axes, labels)


def _grid(axes: list[list[tuple[str, float]]], labels: list[str]) -> Iterator[tuple[str, dict]]:
    from advgame.adversaries import ConstantAdversary

    for combo in itertools.product(*axes):
        values: dict[str, list[float]] = {}
        for agent, v in combo:
            values.setdefault(agent, []).append(v)
        name = ",".join(f"{lab}={v:.6g}" for lab, (_, v) in zip(labels, combo, strict=True))
        yield name, {a: ConstantAdversary(tuple(vs)) for a, vs in values.items()}
