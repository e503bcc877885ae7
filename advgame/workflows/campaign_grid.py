"""A campaign file: the grid (scenario, methods × seeds, budgets) and its evaluation, checked.

`load_campaign` reads the TOML file (see `advgame.workflows.campaign` for its layout) into a
`Campaign`, which checks every field when it is made: each run's `TrainConfig`, and the
``[evaluate]`` section as the evaluation will read it (the threat model is a preset of the
scenario, the column specs parse and build, the optimal attack has an observation budget),
so a typo stops the campaign before hours of training rather than after.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from advgame.errors import ConfigError

if TYPE_CHECKING:
    from advgame.evaluation.attacks.optimal import OptimalSearch

__all__ = ["Campaign", "load_campaign"]

_LABEL = re.compile(r"[a-z0-9][a-z0-9._-]*")
"""What a campaign's method name may be (it names run folders and zoo entries)."""
_RUN = re.compile(r".*-s[0-9]+")
"""A run name's ending; a method name must not have it (``NAME-sSEED`` splits at the last)."""


@dataclass(frozen=True)
class Campaign:
    """A grid of methods × seeds on one scenario, and how it is evaluated."""

    scenario: str
    """Registered scenario id."""
    methods: tuple[str, ...]
    """Names in `advgame.training.METHODS`, or variants whose `per_method` section names one
    under ``method``."""
    seeds: tuple[int, ...]
    """Training seeds of every method whose section does not give its own ``seeds``."""
    train: Mapping[str, Any] = field(default_factory=dict)
    """`TrainConfig` fields for every run."""
    per_method: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    """`TrainConfig` fields for the runs of one method (over `train`); a variant's also names
    its ``method``, and any section may give the method its own ``seeds`` (more seeds where
    the intervals overlap, without training the other methods again)."""
    adversaries: tuple[str, ...] = ("attacks",)
    """Evaluation column specs."""
    threat: str | None = None
    """The table's threat model (None: `advgame.evaluation.table.columns.default_threat`)."""
    eval_seeds: int = 5
    """Evaluation seeds per cell."""
    exploitability: int = 0
    """Steps of each candidate of the searched optimal attack (0: no optimal column)."""
    cost_limit: float | None = None
    """Episode cost limit of a safe campaign: adds the cost table (None: no cost table)."""
    zoo: str | None = None
    """The zoo folder `--release` puts the median agents in (``ZOO/METHOD``; None: the
    scenario's name in lowercase, ``hopper`` for Hopper-v5): a campaign on a changed task
    (OMPO's shifting Hopper) releases beside the nominal task's agents, not over them."""
    optimal_grid: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    """Overrides of `advgame.evaluation.attacks.optimal.OPTIMAL_GRID` entries, by index (a TOML
    key such as ``4``): ``{"4": {"steps_scale": 10}}`` trains the long recipe candidate 10 times
    the search's steps. Entries keep their index, so the others' part files are read back."""

    def __post_init__(self) -> None:
        from advgame.training import METHODS

        unknown = [m for m in self.methods if self.base_method(m) not in METHODS]
        if not self.methods or unknown:
            raise ConfigError(
                f"Campaign methods must be names of advgame.training.METHODS {sorted(METHODS)} "
                f"or variants whose [train.NAME] section names one as `method`, got "
                f"{list(self.methods)!r}."
            )
        odd = [m for m in self.methods if not _LABEL.fullmatch(m) or _RUN.fullmatch(m)]
        if odd or len(set(self.methods)) != len(self.methods):
            raise ConfigError(
                f"Campaign method names must be distinct, lowercase letters, digits, '-', '_' "
                f"or '.', and not end in -s<digits> (run names do), got {list(self.methods)!r}."
            )
        stray = set(self.per_method) - set(self.methods)
        if stray:
            raise ConfigError(f"[train.{sorted(stray)[0]}] names no method of the campaign.")
        for where, seeds in [("seeds", self.seeds)] + [
            (f"[train.{m}] seeds", own["seeds"])
            for m, own in self.per_method.items()
            if "seeds" in own
        ]:
            if (
                not isinstance(seeds, list | tuple)
                or not seeds
                or not all(type(s) is int and s >= 0 for s in seeds)
                or len(set(seeds)) != len(seeds)
            ):
                raise ConfigError(
                    f"Campaign {where} must be a list of distinct ints >= 0, got {seeds!r}."
                )
        if type(self.eval_seeds) is not int or self.eval_seeds < 1:
            raise ConfigError(f"evaluate.seeds must be an int >= 1, got {self.eval_seeds!r}.")
        if type(self.exploitability) is not int or self.exploitability < 0:
            raise ConfigError(
                f"evaluate.exploitability must be an int >= 0, got {self.exploitability!r}."
            )
        limit = self.cost_limit
        if limit is not None and (
            isinstance(limit, bool) or not isinstance(limit, int | float) or not limit >= 0
        ):
            raise ConfigError(f"evaluate.cost_limit must be a number >= 0, got {limit!r}.")
        if self.zoo is not None and (
            not isinstance(self.zoo, str) or not _LABEL.fullmatch(self.zoo)
        ):
            raise ConfigError(
                f"Campaign zoo must be a folder name (lowercase letters, digits, '-', '_', '.'), "
                f"got {self.zoo!r}."
            )
        self.search_grid()  # refuses a bad override before anything trains
        from advgame.training.conditions import check_presets

        conditions = set()
        for name in self.runs():  # every TrainConfig is checked before anything runs
            conditions.add(tuple(self.config(name).eval_conditions or ()))
        for wanted in conditions:  # and the in-training evaluation's presets exist
            check_presets(self.scenario, wanted)
        self._check_evaluation()

    def search_grid(self) -> tuple[Mapping[str, Any], ...] | None:
        """The optimal attack's grid with `optimal_grid`'s overrides (None: no override)."""
        from advgame.evaluation.attacks.optimal import OPTIMAL_GRID, OptimalSearch

        if not self.optimal_grid:
            return None
        if not isinstance(self.optimal_grid, Mapping):
            raise ConfigError(
                f"evaluate.optimal_grid must be a table of entry index = {{overrides}}, got "
                f"{self.optimal_grid!r}."
            )
        grid = [dict(g) for g in OPTIMAL_GRID]
        for key, change in self.optimal_grid.items():
            index = int(key) if str(key).isdigit() else -1
            if not 0 <= index < len(grid) or not isinstance(change, Mapping):
                raise ConfigError(
                    f"evaluate.optimal_grid: {key!r} = {change!r} must be an OPTIMAL_GRID index "
                    f"(0 to {len(grid) - 1}) = a table of overrides, e.g. 4 = {{ steps_scale = 10 }}."
                )
            grid[index].update(change)
        try:
            OptimalSearch(steps=max(self.exploitability, 1), grid=tuple(grid))
        except ConfigError as exc:
            raise ConfigError(f"evaluate.optimal_grid: {exc}") from None
        return tuple(grid)

    def search(self, workers: int = 1) -> OptimalSearch | None:
        """The `OptimalSearch` the evaluate stage runs (None: ``exploitability = 0``, no search)."""
        from advgame.evaluation.attacks.optimal import optimal_search

        return optimal_search(self.exploitability, self.search_grid(), workers=workers)

    def _check_evaluation(self) -> None:
        """The [evaluate] section as the evaluation will read it, hours of training earlier."""
        from advgame.evaluation.table.columns import check_columns

        if not isinstance(self.adversaries, tuple) or not all(
            isinstance(a, str) for a in self.adversaries
        ):
            raise ConfigError(
                f"evaluate.adversaries must be a list of column specs (strings such as "
                f"'attacks', 'attack:mad', 'preset:NAME'), got {self.adversaries!r}."
            )
        if self.threat is not None and not isinstance(self.threat, str):
            raise ConfigError(f"evaluate.threat must be a preset name, got {self.threat!r}.")
        try:
            check_columns(
                self.scenario, self.adversaries, self.threat, attacked=self.exploitability > 0
            )
        except ConfigError as exc:
            raise ConfigError(f"[evaluate]: {exc}") from None

    def base_method(self, method: str) -> str:
        """The `advgame.training.METHODS` name `method` trains with (itself, or its variant's)."""
        return str(self.per_method.get(method, {}).get("method", method))

    def method_seeds(self, method: str) -> tuple[int, ...]:
        """The training seeds of `method`: its section's ``seeds``, else the campaign's."""
        return tuple(self.per_method.get(method, {}).get("seeds", self.seeds))

    def runs(self) -> list[str]:
        """Run names, ``METHOD-sSEED``, method by method."""
        return [f"{m}-s{s}" for m in self.methods for s in self.method_seeds(m)]

    def method_runs(self, method: str) -> list[str]:
        """The runs of one method (``atla`` is not ``atla-sa``)."""
        return [r for r in self.runs() if r.rpartition("-s")[0] == method]

    def config(self, run: str) -> Any:
        """The `TrainConfig` of run ``METHOD-sSEED``."""
        from advgame.training import METHODS, TrainConfig

        method, _, seed = run.rpartition("-s")
        own = {
            k: v for k, v in self.per_method.get(method, {}).items() if k not in ("method", "seeds")
        }
        base = METHODS[self.base_method(method)]
        fields = {**base, **self.train, **own}
        hparams = [d.get("protagonist_hparams") for d in (base, self.train, own)]
        if sum(h is not None for h in hparams) > 1 and all(
            isinstance(h, Mapping) for h in hparams if h is not None
        ):  # a method's own settings (a matched control's) stay under the campaign's overrides
            fields["protagonist_hparams"] = {k: v for h in hparams if h for k, v in h.items()}
        try:
            return TrainConfig(scenario=self.scenario, seed=int(seed), **fields)
        except TypeError as exc:
            raise ConfigError(
                f"Run {run}: a [train] key is not a TrainConfig field ({exc})."
            ) from None


def load_campaign(path: str | Path) -> Campaign:
    """Read a campaign file (TOML; see the module doc)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"No campaign file at {path}.") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"The campaign file {path} is not valid TOML: {exc}.") from None
    known = {"scenario", "methods", "seeds", "zoo", "train", "evaluate"}
    if set(data) - known:
        raise ConfigError(f"{path}: unknown keys {sorted(set(data) - known)}; use {sorted(known)}.")
    train = dict(data.get("train", {}))
    methods = tuple(data.get("methods", ()))
    per_method = {
        m: train.pop(m) for m in list(train) if isinstance(train[m], dict) and m in methods
    }
    ev = dict(data.get("evaluate", {}))
    known_ev = {"adversaries", "threat", "seeds", "exploitability", "cost_limit", "optimal_grid"}
    unknown = set(ev) - known_ev
    if unknown:
        raise ConfigError(f"{path}: unknown [evaluate] keys {sorted(unknown)}.")
    return Campaign(
        scenario=str(data.get("scenario", "")),
        methods=methods,
        seeds=_specs(data.get("seeds", (0,))),
        zoo=data.get("zoo"),
        train=train,
        per_method=per_method,
        adversaries=_specs(ev.get("adversaries", ("attacks",))),
        threat=ev.get("threat"),
        eval_seeds=ev.get("seeds", 5),
        exploitability=ev.get("exploitability", 0),
        cost_limit=ev.get("cost_limit"),
        optimal_grid=ev.get("optimal_grid", {}),
    )


def _specs(value: Any) -> Any:
    """A list (column specs, seeds) as a tuple; anything else is left for the check to refuse."""
    return tuple(value) if isinstance(value, list | tuple) else value
