"""Against whom: adversary columns of a payoff table from short specs, one registry entry a kind.

A column spec is ``KIND[:ARG][,KEY=VALUE...]``; `adversary_columns` turns a list of them into
named `AdversarySetup`s (``nominal`` always first, the metrics are relative to it)::

    nominal                      the undisrupted game
    preset:NAME                  a preset played by its suggested adversaries
    random                       the paper's random presets the scenario has
    scheduled                    the scenario's scheduled preset
    learned[:RUN_DIR]            the latest learned snapshot of each adversary of a run (no
                                 RUN_DIR: of every evaluated run)
    population:RUN_DIR|FILE      every learned snapshot, one column per iteration; options
                                 last=K, sample=K, preset=NAME (a file outside a run dir)
    attack:random|mad|critic|rs  an attack on the threat model's observation disruptor: noise
                                 filling its budget, or a white-box attack on each protagonist's
                                 own networks (`advgame.adversaries.whitebox`); ``rs`` is Robust
                                 Sarsa (`advgame.adversaries.robust_sarsa`; options samples=N,
                                 epochs=N for its critic)
    attack:max-cost              safe scenarios: Liu et al.'s maximum-cost attack, towards the
                                 action a learned cost critic values most (options as rs)
    attack:pa-ad                 PA-AD: a director learned against each protagonist picks a
                                 direction in its actions, a white-box walk pushes the action
                                 there (`advgame.adversaries.paad`; option samples=N: the
                                 director's training steps, default 200k)
    attacks                      the worst-of-attacks suite: attack:random, attack:mad,
                                 attack:critic (skipped for teams: their actors have no critic),
                                 attack:rs and every evaluated run's learned adversaries
    default                      nominal, random, scheduled, learned (``advgame evaluate``'s)

**One threat model per table.** A table compares protagonists like for like only if every one
of them is attacked in the same disruptors and budgets. The *threat model* is a preset of the
scenario (`ColumnContext.threat`; `default_threat` picks ``atla`` where the scenario has ATLA's
budgets, else ``default``): attack columns, learned columns (a run's adversaries replayed in its
budget) and best responses all use it, whatever preset each protagonist was trained in. A
column's ``preset=NAME`` option overrides it for that column alone. Learned adversaries that do
not fit the *default* threat model (other agents or action shapes, e.g. a partial attack on one
agent of a team) play in the preset they were trained in; with a threat model given, a misfit
is an error.

A new kind is one function ``(ColumnContext, arg, options) -> {name: AdversarySetup}`` added
to `COLUMN_KINDS`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from advgame.errors import ConfigError, UnknownNameError, did_you_mean
from advgame.evaluation.table.jobs import AdversarySetup
from advgame.evaluation.table.payoff import NOMINAL
from advgame.evaluation.table.snapshots import misfit, snapshots
from advgame.evaluation.table.threat import default_threat, observation_agent

__all__ = [
    "ATTACKS",
    "COLUMN_KINDS",
    "DEFAULT_COLUMNS",
    "RANDOM",
    "SAFE_RANDOM",
    "SCHEDULED",
    "ColumnContext",
    "adversary_columns",
    "default_threat",
    "describe_column",
]

RANDOM = ("state-gauss-0.1", "state-gauss-0.15", "state-uniform-0.2-0.8", "action-gauss-0.1")
"""Random-mode presets of the ``random`` kind, where the scenario has them (the paper's)."""
SAFE_RANDOM = ("action-gauss-0.15", "action-gauss-0.3", "cost-gauss-0.15", "cost-gauss-0.3")
"""Added to ``random`` on safe scenarios: the paper's safe-RL settings (action and observed-cost
noise)."""
SCHEDULED = ("shift-sinusoid", "state-gauss-0.1-100F")
"""The first of these the scenario has is the ``scheduled`` column."""
DEFAULT_COLUMNS = ("nominal", "random", "scheduled", "learned")
"""What ``default`` expands to: today's ``advgame evaluate`` columns."""


@dataclass(frozen=True)
class ColumnContext:
    """What column kinds may read besides their own spec."""

    scenario: str
    """The evaluated scenario id."""
    runs: Mapping[str, Path] = field(default_factory=dict)
    """The evaluated runs, ``{name: run directory}`` (for ``learned`` without a run)."""
    last: int | None = None
    """Default ``last=K`` of population columns."""
    sample: int | None = None
    """Default ``sample=K`` of population columns."""
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    """Draws the snapshots of ``sample=K``."""
    protagonists: Mapping[str, Any] = field(default_factory=dict)
    """The evaluated protagonists' specs, ``{name: spec}`` (for kinds that attack them)."""
    threat: str | None = None
    """The threat model given by the user: the preset whose disruptors and budgets attack,
    learned and best-response columns play in (``None``: `default_threat`, see the module doc)."""


Kind = Callable[[ColumnContext, str, Mapping[str, str]], dict[str, AdversarySetup]]


def _nominal(ctx: ColumnContext, arg: str, opts: Mapping[str, str]) -> dict[str, AdversarySetup]:
    return {NOMINAL: AdversarySetup.nominal()}


def _preset(ctx: ColumnContext, arg: str, opts: Mapping[str, str]) -> dict[str, AdversarySetup]:
    if not arg:
        raise ConfigError("preset: needs a name, e.g. preset:state-gauss-0.1.")
    return {f"preset {arg}": AdversarySetup.from_preset(ctx.scenario, arg)}


def _random(ctx: ColumnContext, arg: str, opts: Mapping[str, str]) -> dict[str, AdversarySetup]:
    from advgame.core.registry import scenario_spec

    spec = scenario_spec(ctx.scenario)
    presets = spec.load_presets()
    names = RANDOM + (SAFE_RANDOM if spec.family == "safe" else ())
    return {
        f"random {n}": AdversarySetup.from_preset(ctx.scenario, n) for n in names if n in presets
    }


def _scheduled(ctx: ColumnContext, arg: str, opts: Mapping[str, str]) -> dict[str, AdversarySetup]:
    from advgame.core.registry import scenario_spec

    presets = scenario_spec(ctx.scenario).load_presets()
    for name in SCHEDULED:
        if name in presets:
            return {f"scheduled {name}": AdversarySetup.from_preset(ctx.scenario, name)}
    return {}


def _learned(ctx: ColumnContext, arg: str, opts: Mapping[str, str]) -> dict[str, AdversarySetup]:
    runs = {Path(arg).name: Path(arg)} if arg else dict(ctx.runs)
    cols = {}
    for name, run_dir in runs.items():
        if not arg and not (run_dir / "population.json").is_file():
            continue  # an evaluated run without a population has no learned column
        preset, snaps = snapshots(run_dir, opts)
        latest = {agent: m for it in sorted(snaps) for agent, m in snaps[it].items()}
        if latest:
            cols[f"learned ({name})"] = _learned_setup(ctx, preset, latest, opts)
    return cols


def _population(ctx: ColumnContext, arg: str, opts: Mapping[str, str]) -> dict[str, AdversarySetup]:
    if not arg:
        raise ConfigError("population: needs a run directory or file, e.g. population:runs/atla.")
    preset, snaps = snapshots(Path(arg), opts)
    its = _select(sorted(snaps), opts, ctx)
    path = Path(arg)
    source = path.parent.name if path.name == "population.json" else path.stem
    return {f"population {source}@{it}": _learned_setup(ctx, preset, snaps[it], opts) for it in its}


OPTIONS = ("last", "sample", "preset", "samples", "epochs")
"""The ``KEY=VALUE`` options a column spec may carry."""
ATTACKS = ("random", "mad", "critic", "rs")
"""The attacks of the ``attacks`` suite (in this order)."""
ATTACK_KINDS = (*ATTACKS, "max-cost", "pa-ad")
"""The attacks of the ``attack:`` kind: the suite's, the safe-RL max-cost attack and PA-AD."""


def _attack(ctx: ColumnContext, arg: str, opts: Mapping[str, str]) -> dict[str, AdversarySetup]:
    from advgame.adversaries import (
        CriticAttack,
        MADAttack,
        MaxCostAttack,
        PAADAttack,
        RandomAdversary,
        RobustSarsaAttack,
    )

    if arg not in ATTACK_KINDS:
        hint = did_you_mean(arg, ATTACK_KINDS)
        raise UnknownNameError(
            f"Unknown attack {arg!r}.{hint} Attacks: attack:{', attack:'.join(ATTACK_KINDS)}."
        )
    preset = opts.get("preset") or ctx.threat or default_threat(ctx.scenario)
    agent = observation_agent(ctx.scenario, preset)
    kinds = {
        "mad": MADAttack, "critic": CriticAttack, "rs": RobustSarsaAttack,
        "max-cost": MaxCostAttack, "pa-ad": PAADAttack,
    }  # fmt: skip
    learned = arg in ("rs", "max-cost")
    options = {k: _count(opts, k, None) for k in ("samples", "epochs") if learned and k in opts}
    if arg == "pa-ad" and "samples" in opts:  # the director's training steps
        options = {"director_steps": _count(opts, "samples", None)}
    spec = RandomAdversary() if arg == "random" else kinds[arg](**options)
    return {f"attack {arg}": AdversarySetup({"preset": preset}, {agent: spec})}


def _attacks(ctx: ColumnContext, arg: str, opts: Mapping[str, str]) -> dict[str, AdversarySetup]:
    teams = any(isinstance(spec, Mapping) for spec in ctx.protagonists.values())
    cols: dict[str, AdversarySetup] = {}
    for name in ATTACKS:
        if not (teams and name == "critic"):
            cols.update(_attack(ctx, name, opts))
    cols.update(_learned(ctx, "", opts))
    return cols


def _default(ctx: ColumnContext, arg: str, opts: Mapping[str, str]) -> dict[str, AdversarySetup]:
    cols: dict[str, AdversarySetup] = {}
    for kind in DEFAULT_COLUMNS:
        cols.update(COLUMN_KINDS[kind](ctx, "", {}))
    return cols


COLUMN_KINDS: dict[str, Kind] = {
    "nominal": _nominal,
    "preset": _preset,
    "random": _random,
    "scheduled": _scheduled,
    "learned": _learned,
    "population": _population,
    "attack": _attack,
    "attacks": _attacks,
    "default": _default,
}
"""Column kinds by name: ``(context, argument, options) -> {column name: AdversarySetup}``."""


def _learned_setup(
    ctx: ColumnContext, trained_in: str, members: Mapping[str, Any], opts: Mapping[str, str]
) -> AdversarySetup:
    """Learned snapshots replayed (deterministically) in the table's threat model.

    The column's ``preset=`` option or an explicit threat model must fit the adversaries (same
    agents, same action shapes), else it is an error. Without either, they play in the default
    threat model where they fit, else in the preset they were trained in (e.g. a partial attack
    on one agent of a team cannot act in a budget over every agent).
    """
    specs = {a: replace(m.spec, deterministic=True) for a, m in members.items()}
    chosen = opts.get("preset") or ctx.threat
    if chosen:
        problem = misfit(ctx.scenario, chosen, specs)
        if problem:
            raise ConfigError(
                f"{problem}; evaluate in the preset they were trained in ({trained_in!r}) with "
                "--threat or the column's preset=NAME."
            )
        return AdversarySetup({"preset": chosen}, specs)
    shared = default_threat(ctx.scenario)
    preset = trained_in if misfit(ctx.scenario, shared, specs) else shared
    return AdversarySetup({"preset": preset}, specs)


def _select(iterations: list[int], opts: Mapping[str, str], ctx: ColumnContext) -> list[int]:
    last = _count(opts, "last", ctx.last)
    sample = _count(opts, "sample", ctx.sample)
    if last is not None and sample is not None:
        raise ConfigError(f"Give last=K or sample=K, not both (got last={last}, sample={sample}).")
    if last is not None:
        return iterations[-last:]
    if sample is not None and sample < len(iterations):
        picked = ctx.rng.choice(len(iterations), size=sample, replace=False)
        return [iterations[i] for i in sorted(picked)]
    return iterations


def _count(opts: Mapping[str, str], key: str, default: int | None) -> int | None:
    if key not in opts:
        return default
    try:
        value = int(opts[key])
    except ValueError:
        value = 0
    if value < 1:
        raise ConfigError(f"{key}={opts[key]!r} must be an int >= 1: write {key}=K with K >= 1.")
    return value


def parse_spec(spec: str) -> tuple[str, str, dict[str, str]]:
    """Split ``KIND[:ARG][,KEY=VALUE...]`` into its kind, argument and options."""
    head, *rest = spec.split(",")
    kind, _, arg = head.partition(":")
    if kind not in COLUMN_KINDS:
        hint = did_you_mean(kind, COLUMN_KINDS)
        raise UnknownNameError(
            f"Unknown adversary column kind {kind!r} in {spec!r}.{hint} Kinds: {list(COLUMN_KINDS)}"
        )
    opts = {}
    for item in rest:
        key, sep, value = item.partition("=")
        if not sep or key not in OPTIONS:
            raise ConfigError(
                f"Bad option {item!r} in {spec!r}; options are last=K, sample=K, preset=NAME "
                "(populations), samples=N, epochs=N (the Robust Sarsa critic of attack:rs; samples=N: "
                "the PA-AD director's training steps)."
            )
        opts[key] = value
    return kind, arg, opts


def adversary_columns(
    scenario: str,
    specs: Sequence[str] = ("default",),
    *,
    runs: Mapping[str, str | Path] | None = None,
    last: int | None = None,
    sample: int | None = None,
    seed: int = 0,
    protagonists: Mapping[str, Any] | None = None,
    threat: str | None = None,
) -> dict[str, AdversarySetup]:
    """The adversary columns `specs` name, ``nominal`` first (see the module doc for kinds).

    `runs` are the evaluated runs (``learned`` and ``default`` use them); `last` and `sample`
    are the defaults of population columns that set neither; `seed` draws ``sample=K``;
    `protagonists` (``{name: spec}``) are passed on to kinds that need them; `threat` is the
    table's threat model (see the module doc; ``None``: the default one).
    """
    if isinstance(specs, str):
        specs = [specs]
    ctx = ColumnContext(
        scenario,
        {n: Path(d) for n, d in (runs or {}).items()},
        _count({"last": str(last)}, "last", None) if last is not None else None,
        _count({"sample": str(sample)}, "sample", None) if sample is not None else None,
        np.random.default_rng(seed),
        dict(protagonists or {}),
        threat,
    )
    cols: dict[str, AdversarySetup] = {NOMINAL: AdversarySetup.nominal()}
    for spec in specs:
        kind, arg, opts = parse_spec(spec)
        cols.update(COLUMN_KINDS[kind](ctx, arg, opts))
    return cols


def check_columns(
    scenario: str, specs: Sequence[str], threat: str | None = None, *, attacked: bool = False
) -> None:
    """Refuse, before anything runs, column specs that `adversary_columns` would refuse later.

    Every spec is parsed and every column that reads no file is built (presets, attacks and
    their budgets in the threat model); ``learned`` and ``population`` columns, whose runs
    may not exist yet, are checked for their syntax only. `threat` must be a preset of
    `scenario`; `attacked` (an optimal-attack search or released adversaries) also needs it
    to have a bounded observation disruptor. The errors are `adversary_columns`' own.
    """
    from advgame.core.registry import scenario_spec

    if threat is not None:
        presets = scenario_spec(scenario).load_presets()
        if threat not in presets:
            hint = did_you_mean(threat, presets)
            raise UnknownNameError(
                f"Scenario {scenario!r} has no preset {threat!r} (the threat model).{hint} "
                f"Its presets: {sorted(presets)}."
            )
    if attacked:
        observation_agent(scenario, threat or default_threat(scenario))
    if isinstance(specs, str):
        specs = [specs]
    playable = [s for s in specs if parse_spec(s)[0] not in ("learned", "population")]
    adversary_columns(scenario, playable, threat=threat)


def describe_column(setup: AdversarySetup) -> dict[str, Any]:
    """A JSON-friendly description of a column: its game options and each adversary's spec."""
    import dataclasses

    def spec_text(spec: Any) -> str:
        if dataclasses.is_dataclass(spec) and not isinstance(spec, type):
            fields = ", ".join(f"{k}={v!r}" for k, v in dataclasses.asdict(spec).items())
            return f"{type(spec).__name__}({fields})"
        return getattr(spec, "__qualname__", None) or repr(spec)

    return {
        "game": {k: v for k, v in setup.make_kwargs.items() if k != "phase"},
        "adversaries": {a: spec_text(s) for a, s in setup.specs.items()} or "none (no-ops)",
    }
