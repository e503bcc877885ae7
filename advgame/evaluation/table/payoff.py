"""The payoff table: episode rows of protagonists × adversaries × seeds, and robust metrics.

Metrics are computed on the *true* return (the reward before any reward disruptor): nominal,
mean, worst case, CVaR and the degradation from nominal. Tables save to CSV and JSON.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from advgame.core.files import read_csv, read_json, reading, require
from advgame.errors import ConfigError, FileFormatError, did_you_mean

__all__ = [
    "COLUMNS",
    "NOMINAL",
    "NOT_APPLICABLE",
    "PayoffTable",
    "ci95",
    "cvar",
    "degradation",
    "worst_case",
]

NOMINAL = "nominal"
"""The adversary name of the undisrupted game, the reference of `degradation`."""
NOT_APPLICABLE = "not_applicable"
"""The file column holding why a cell was not played (`PayoffTable.not_applicable`)."""
COLUMNS: tuple[str, ...] = ("scenario", "protagonist", "adversary", "seed", "episode")
COLUMNS += ("true_return", "observed_return", "cost", "payoff", "length", "clipped", "terminated")
"""The columns of every row (`advgame.core.episodes.EpisodeResult`, clips summed); tags add more."""
_INT, _STR = {"seed", "episode", "length", "clipped"}, {"scenario", "protagonist", "adversary"}
_KEYS = ("protagonist", "adversary", "seed", "true_return")
"""Columns a payoff file must give on every row to be read back."""
RESULTS_FIX = (
    "Run `advgame evaluate` again with the same --out (it rewrites the results), or delete "
    "the folder."
)
"""How to recover from a damaged results file."""
# Student t 0.975 quantiles for df = 1..30 (95 % two-sided intervals); 1.96 beyond.
_T975: tuple[float, ...] = (
    12.706,
    4.303,
    3.182,
    2.776,
    2.571,
    2.447,
    2.365,
    2.306,
    2.262,
    2.228,
    2.201,
    2.179,
)
_T975 += (2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064)
_T975 += (2.060, 2.056, 2.052, 2.048, 2.045, 2.042)


# -- metrics: pure functions ----------------------------------------------------------------
def cvar(values: Sequence[float] | np.ndarray, alpha: float = 0.1) -> float:
    """Return CVaR_α of returns: the mean of the ``k = ⌈α·n⌉`` lowest of the ``n`` values.

    ``α·n`` is rounded to 9 decimals before the ceiling, so ``α = 0.3, n = 10`` takes the 3
    lowest (not 4 through floating-point error). ``α = 1`` is the plain mean.

    Example:
        >>> cvar([5.0, 1.0, 3.0, 2.0], alpha=0.5)
        1.5

    """
    v = np.sort(np.asarray(values, dtype=np.float64).ravel())
    if not 0.0 < alpha <= 1.0:
        raise ConfigError(f"CVaR needs 0 < alpha <= 1, got alpha={alpha!r}; e.g. alpha=0.1.")
    if v.size == 0:
        raise ConfigError("CVaR of no values is undefined; evaluate at least one episode.")
    k = max(1, math.ceil(round(alpha * v.size, 9)))
    return float(v[:k].mean())


def worst_case(cell_means: Mapping[str, float] | Sequence[float]) -> float:
    """Return the worst-case return: the lowest per-adversary cell mean (nan if one is nan)."""
    vals = list(cell_means.values()) if isinstance(cell_means, Mapping) else list(cell_means)
    if not vals:
        raise ConfigError("worst_case needs at least one cell mean, got none.")
    return float(np.min(np.asarray(vals, dtype=np.float64)))


def degradation(nominal: float, value: float) -> float:
    """Return the relative loss ``(nominal - value) / |nominal|``; nan if nominal is 0 or nan."""
    if not math.isfinite(nominal) or nominal == 0:
        return math.nan
    return (nominal - value) / abs(nominal)


def ci95(values: Sequence[float] | np.ndarray) -> float:
    """Return the half-width of the 95 % Student-t interval of the mean (nan for n < 2)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size < 2:
        return math.nan
    t = _T975[v.size - 2] if v.size - 1 <= len(_T975) else 1.96
    return float(t * v.std(ddof=1) / math.sqrt(v.size))


# -- jobs -----------------------------------------------------------------------------------
# -- the payoff table -----------------------------------------------------------------------
def _check_played(rows: Sequence[Mapping[str, Any]], path: str | Path) -> None:
    """Every row read back has the key cells (a cell not applicable needs only its two names)."""
    for i, row in enumerate(rows, start=2):
        keys = _KEYS[:2] if row.get(NOT_APPLICABLE) else _KEYS
        if any(row.get(c) in (None, "") for c in keys):
            raise FileFormatError(
                f"The payoff table {path} has a short or broken row {i - 1} (it lacks one of "
                f"{list(keys)}); it looks truncated or edited. {RESULTS_FIX}",
                path=str(path),
            )


def _parse(key: str, text: str) -> Any:
    if key in _STR:
        return text
    if key in _INT:
        return int(text)
    if text in ("True", "False"):
        return text == "True"
    try:
        return float(text)
    except ValueError:
        return text


class PayoffTable:
    """Episode rows (protagonist × adversary × seed × episode) and the robust metrics on them.

    Args:
        rows: dicts with at least ``protagonist``, ``adversary``, ``seed`` and ``true_return``.
        not_applicable: ``{(protagonist, adversary): reason}`` for cells that were not played
            because the column cannot play that row (e.g. a white-box attack against a fixed
            controller). They show as "n/a" in matrices and reports and are left out of every
            metric; the files keep them (one row per cell with a ``not_applicable`` reason).

    Example:
        >>> t = PayoffTable([{"protagonist": "p", "adversary": a, "seed": 0, "true_return": r}
        ...                  for a, r in [("nominal", 10.0), ("gauss", 6.0), ("push", 4.0)]])
        >>> m = t.metrics(alpha=0.5)[0]
        >>> m["mean"], m["worst"], m["worst_adversary"], m["degradation"]
        (5.0, 4.0, 'push', 0.5)

    """

    def __init__(
        self,
        rows: Iterable[Mapping[str, Any]] = (),
        not_applicable: Mapping[tuple[str, str], str] | None = None,
    ) -> None:
        self.rows: list[dict[str, Any]] = [dict(r) for r in rows]
        for r in self.rows:
            missing = {"protagonist", "adversary", "seed", "true_return"} - r.keys()
            if missing:
                raise ConfigError(f"Payoff row {r} lacks the columns {sorted(missing)}.")
        self.not_applicable: dict[tuple[str, str], str] = dict(not_applicable or {})
        """``{(protagonist, adversary): reason}``: cells the column could not play."""

    def __len__(self) -> int:
        return len(self.rows)

    def __repr__(self) -> str:
        ps, adv = self.protagonists, self.adversaries
        return f"PayoffTable({len(self)} rows, protagonists={ps}, adversaries={adv})"

    @property
    def protagonists(self) -> list[str]:
        """Protagonist names in order of first appearance (cells not applicable included)."""
        played = (r["protagonist"] for r in self.rows)
        return list(dict.fromkeys([*played, *(p for p, _ in self.not_applicable)]))

    @property
    def adversaries(self) -> list[str]:
        """Adversary names in order of first appearance (cells not applicable included)."""
        played = (r["adversary"] for r in self.rows)
        return list(dict.fromkeys([*played, *(a for _, a in self.not_applicable)]))

    def columns(self) -> list[str]:
        """Return the `COLUMNS` present in the rows, then the other (tag) columns, sorted."""
        keys = dict.fromkeys(k for r in self.rows for k in r)
        return [c for c in COLUMNS if c in keys] + sorted(k for k in keys if k not in COLUMNS)

    def values(self, protagonist: str, adversary: str, column: str = "true_return") -> np.ndarray:
        """Return `column` of every episode of one cell (empty if the cell was not played)."""
        rows = self.rows
        sel = [r for r in rows if r["protagonist"] == protagonist and r["adversary"] == adversary]
        return np.array([float(r[column]) for r in sel])

    def seed_means(self, protagonist: str, adversary: str) -> np.ndarray:
        """Return a cell's mean true return per seed (what its interval is computed over)."""
        by_seed: dict[Any, list[float]] = {}
        for r in self.rows:
            if r["protagonist"] == protagonist and r["adversary"] == adversary:
                by_seed.setdefault(r["seed"], []).append(float(r["true_return"]))
        return np.array([np.mean(v) for v in by_seed.values()])

    def matrix(
        self, stat: str = "mean", column: str = "true_return"
    ) -> tuple[list[str], list[str], np.ndarray]:
        """Return ``(protagonists, adversaries, M)``, M the `stat` of `column` in each cell.

        `stat` is ``"mean"``, ``"median"``, ``"std"``, ``"min"`` or ``"max"`` over the cell's
        episodes; cells not played are nan.
        """
        fns: dict[str, Callable[..., Any]] = {
            "mean": np.mean,
            "median": np.median,
            "std": np.std,
            "min": np.min,
            "max": np.max,
        }
        if stat not in fns:
            raise ConfigError(f"Unknown stat {stat!r}.{did_you_mean(stat, fns)} Use {sorted(fns)}.")
        ps, adv = self.protagonists, self.adversaries
        m = np.full((len(ps), len(adv)), np.nan)
        for (i, p), (j, a) in itertools.product(enumerate(ps), enumerate(adv)):
            v = self.values(p, a, column)
            m[i, j] = fns[stat](v) if v.size else np.nan
        return ps, adv, m

    def cells(self) -> list[dict[str, Any]]:
        """Per played cell: episodes, seeds, mean, min, max; std and ci95 over seed means."""
        out = []
        for p, a in itertools.product(self.protagonists, self.adversaries):
            v, s = self.values(p, a), self.seed_means(p, a)
            if v.size:
                std = float(s.std(ddof=1)) if s.size > 1 else math.nan
                stats = {"mean": v.mean(), "std": std, "ci95": ci95(s)}
                stats.update({"min": v.min(), "max": v.max()})
                cell = {"protagonist": p, "adversary": a, "episodes": v.size, "seeds": s.size}
                out.append({**cell, **{k: float(x) for k, x in stats.items()}})
        return out

    def metrics(self, alpha: float = 0.1, nominal: str = NOMINAL) -> list[dict[str, Any]]:
        """Return robust metrics of the true return, one dict per protagonist.

        ``nominal``: the mean in the `nominal` column (nan if absent). Over all other columns:
        ``mean`` of their episodes; ``worst`` the lowest cell mean (`worst_case`), in column
        ``worst_adversary``; ``cvar`` the `cvar` of their episodes; ``degradation`` and
        ``worst_degradation`` of mean and worst from nominal (`degradation`); ``nominal_ci95``
        and ``worst_ci95`` the 95 % half-widths over seeds of those two cells (`ci95`).
        Cells in `not_applicable` are left out; ``not_applicable`` counts them per protagonist.
        """
        rows = []
        for p in self.protagonists:
            nom_v = self.values(p, nominal)
            cells = {a: self.values(p, a) for a in self.adversaries if a != nominal}
            means = {a: float(v.mean()) for a, v in cells.items() if v.size}
            pooled = np.concatenate([cells[a] for a in means]) if means else np.zeros(0)
            nom = float(nom_v.mean()) if nom_v.size else math.nan
            worst_adv = min(means, key=means.__getitem__) if means else ""
            worst = means[worst_adv] if means else math.nan
            mean = float(pooled.mean()) if means else math.nan
            row = {"protagonist": p, "nominal": nom, "mean": mean, "worst": worst}
            row["worst_adversary"] = worst_adv
            row["cvar"] = cvar(pooled, alpha) if means else math.nan
            row["degradation"] = degradation(nom, mean)
            row["worst_degradation"] = degradation(nom, worst)
            row["nominal_ci95"] = ci95(self.seed_means(p, nominal))
            row["worst_ci95"] = ci95(self.seed_means(p, worst_adv))
            row["not_applicable"] = sum(1 for q, _ in self.not_applicable if q == p)
            rows.append({**row, "adversaries": len(means), "episodes": int(pooled.size)})
        return rows

    @property
    def has_cost(self) -> bool:
        """Whether any episode incurred a true cost (a safe scenario was evaluated)."""
        return any(float(r.get("cost", 0.0) or 0.0) != 0.0 for r in self.rows)

    def safety(self, limit: float) -> list[dict[str, Any]]:
        """Per played cell: mean true return and episode cost, and constraint satisfaction.

        ``cost`` is the mean true episode cost and ``cost_ci95`` its 95 % half-width over
        per-seed means; ``satisfied`` is the share of episodes with cost ≤ `limit`.
        """
        if isinstance(limit, bool) or not isinstance(limit, (int, float)) or not limit >= 0:
            raise ConfigError(f"A cost limit must be a number >= 0, got {limit!r} (e.g. 25).")
        out = []
        for p, a in itertools.product(self.protagonists, self.adversaries):
            sel = [r for r in self.rows if r["protagonist"] == p and r["adversary"] == a]
            if not sel:
                continue
            costs = np.array([float(r.get("cost", 0.0)) for r in sel])
            by_seed: dict[Any, list[float]] = {}
            for r, c in zip(sel, costs, strict=True):
                by_seed.setdefault(r["seed"], []).append(c)
            row = {"protagonist": p, "adversary": a, "episodes": len(sel)}
            row["return"] = float(np.mean([float(r["true_return"]) for r in sel]))
            row["cost"] = float(costs.mean())
            row["cost_ci95"] = ci95([float(np.mean(v)) for v in by_seed.values()])
            row["satisfied"] = float(np.mean(costs <= limit))
            out.append(row)
        return out

    def na_rows(self) -> list[dict[str, Any]]:
        """One row per cell not applicable: protagonist, adversary and the ``not_applicable`` reason."""
        return [
            {"protagonist": p, "adversary": a, NOT_APPLICABLE: reason}
            for (p, a), reason in self.not_applicable.items()
        ]

    def to_csv(self, path: str | Path) -> Path:
        """Write the rows as CSV (`columns` order; missing tags left empty); return the path.

        Cells not applicable follow the episode rows, one row each with only ``protagonist``,
        ``adversary`` and the reason in the ``not_applicable`` column.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fields = self.columns() + ([NOT_APPLICABLE] if self.not_applicable else [])
        with path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=fields, restval="")
            writer.writeheader()
            writer.writerows(self.rows)
            writer.writerows(self.na_rows())
        return path

    @classmethod
    def from_csv(cls, path: str | Path) -> PayoffTable:
        """Read a table written by `to_csv` (numbers parsed back; empty cells dropped).

        Raises:
            FileFormatError: the file is empty, cut short, or lacks the key columns.

        """
        rows = read_csv(path, "payoff table", RESULTS_FIX, columns=_KEYS[:2])
        _check_played(rows, path)
        with reading(path, "payoff table", RESULTS_FIX):
            return cls._split({k: _parse(k, v) for k, v in r.items() if v != ""} for r in rows)

    @classmethod
    def _split(cls, rows: Iterable[Mapping[str, Any]]) -> PayoffTable:
        """A table from rows as the files hold them: episode rows and not-applicable rows."""
        played, na = [], {}
        for r in rows:
            if r.get(NOT_APPLICABLE):
                na[(str(r["protagonist"]), str(r["adversary"]))] = str(r[NOT_APPLICABLE])
            else:
                played.append({k: v for k, v in r.items() if k != NOT_APPLICABLE})
        return cls(played, na)

    def to_json(self, path: str | Path) -> Path:
        """Write ``{"columns": [...], "rows": [...]}`` as JSON; return the path.

        Cells not applicable are rows too, as in `to_csv`.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        data = {"columns": self.columns(), "rows": self.rows + self.na_rows()}
        path.write_text(json.dumps(data, indent=1))
        return path

    @classmethod
    def from_json(cls, path: str | Path) -> PayoffTable:
        """Read a table written by `to_json`.

        Raises:
            FileFormatError: the file is empty, truncated, or not a payoff table.

        """
        data = read_json(path, "payoff table", RESULTS_FIX, kind=dict)
        require(data, ("rows",), path, "payoff table", RESULTS_FIX)
        rows = data["rows"]
        if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
            raise FileFormatError(
                f"The payoff table {path} has rows that are not objects: written by another "
                f"version of advgame or another program. {RESULTS_FIX}",
                path=str(path),
            )
        _check_played(rows, path)
        with reading(path, "payoff table", RESULTS_FIX):
            return cls._split(rows)
