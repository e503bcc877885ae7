"""Robust evaluation: payoff tables of protagonists × adversaries × seeds, and robust metrics.

One `EvalJob` is one cell of the payoff matrix: a protagonist against one adversary set-up over
some seeds. Jobs are pure, picklable values, so `evaluate` runs them in this process or in a
process pool (and the same jobs could be shipped to Ray tasks unchanged). Every episode becomes
one row of a `PayoffTable`, which saves to CSV/JSON and computes the design's robust metrics on
the *true* return: nominal, mean, worst case, CVaR and the degradation from nominal::

    jobs = population_jobs("Hopper-v5", {"mine": my_policy},
                           {"nominal": AdversarySetup.nominal(),
                            "gauss": AdversarySetup.from_preset("Hopper-v5", "state-gauss-0.1")},
                           seeds=(0, 1))
    evaluate(jobs, workers=2).metrics(alpha=0.1)
"""

from __future__ import annotations

import contextlib
import csv
import itertools
import json
import logging
import math
import multiprocessing
import operator
import os
import pickle
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from advgame.errors import ConfigError, UnknownNameError, did_you_mean

__all__ = [
    "COLUMNS", "NOMINAL", "AdversarySetup", "EvalJob", "PayoffTable", "budget_sweep", "ci95",
    "cvar", "degradation", "evaluate", "population_jobs", "run_job", "shift_grid", "worst_case",
]

log = logging.getLogger(__name__)

NOMINAL = "nominal"
"""The adversary name of the undisrupted game, the reference of `degradation`."""
COLUMNS = ("scenario", "protagonist", "adversary", "seed", "episode", "true_return",
           "observed_return", "cost", "payoff", "length", "clipped")
"""The columns of every row; a job's `EvalJob.tags` add more."""
_INT, _STR = {"seed", "episode", "length", "clipped"}, {"scenario", "protagonist", "adversary"}
_T975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179,
         2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064,
         2.060, 2.056, 2.052, 2.048, 2.045, 2.042)  # Student t 0.975 quantile, df = 1..30


# -- metrics: pure functions ----------------------------------------------------------------
def cvar(values: Sequence[float] | np.ndarray, alpha: float = 0.1) -> float:
    """CVaR_α of returns: the mean of the ``k = ⌈α·n⌉`` lowest of the ``n`` values.

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
    """The worst-case return: the minimum of the per-adversary cell means (nan if one is nan)."""
    vals = list(cell_means.values()) if isinstance(cell_means, Mapping) else list(cell_means)
    if not vals:
        raise ConfigError("worst_case needs at least one cell mean, got none.")
    return float(np.min(np.asarray(vals, dtype=np.float64)))


def degradation(nominal: float, value: float) -> float:
    """Relative loss ``(nominal - value) / |nominal|``; nan if nominal is 0 or not finite."""
    if not math.isfinite(nominal) or nominal == 0:
        return math.nan
    return (nominal - value) / abs(nominal)


def ci95(values: Sequence[float] | np.ndarray) -> float:
    """Half-width of the 95 % Student-t interval of the mean of `values` (nan for n < 2)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size < 2:
        return math.nan
    t = _T975[v.size - 2] if v.size - 1 <= len(_T975) else 1.96
    return float(t * v.std(ddof=1) / math.sqrt(v.size))


# -- jobs -----------------------------------------------------------------------------------
def _check_spec(spec: Any, what: str) -> None:
    if not (hasattr(spec, "build") or callable(spec)):
        raise ConfigError(f"{what} is {spec!r}; expected a PolicySpec (build), a Policy "
                          "(reset/act) or a module-level callable observation -> action.")


def _seeds(seeds: Any, episodes: int) -> tuple[int, ...]:
    try:
        out = tuple(operator.index(s) for s in ((seeds,) if np.ndim(seeds) == 0 else seeds))
    except TypeError:
        raise ConfigError(f"seeds must be ints, got {seeds!r}; e.g. seeds=(0, 1, 2).") from None
    if not out or min(out) < 0 or isinstance(seeds, bool):
        raise ConfigError(f"seeds must be a non-empty tuple of ints >= 0, got {seeds!r}.")
    resets = [s + i for s in out for i in range(episodes)]
    if len(set(resets)) != len(resets):
        raise ConfigError(
            f"seeds={out} with episodes={episodes} replay the same episodes: episode i of seed s "
            f"resets with seed s + i. Space the seeds at least {episodes} apart, e.g. "
            f"seeds={tuple(range(0, episodes * len(out), episodes))}.")
    return out


@dataclass(frozen=True, kw_only=True)
class EvalJob:
    """One payoff-matrix cell: a protagonist against one adversary set-up, over seeds.

    A pure, picklable value: everything in it must pickle (specs, module-level functions),
    so it can run in a worker process or a Ray task.
    """

    scenario: str
    """Registered scenario id, e.g. ``"Hopper-v5"``."""
    make_kwargs: Mapping[str, Any] = field(default_factory=dict)
    """Keyword arguments of `advgame.make` (``preset=`` or ``disruptors=``, task options);
    ``phase`` defaults to ``"eval"``."""
    protagonist: str
    """The protagonist's name (a row label of the matrix)."""
    protagonist_spec: Any
    """A `PolicySpec`, a `Policy` or a picklable module-level callable ``obs -> action``, used
    for every protagonist; or a dict ``{protagonist agent id: spec}``."""
    adversary: str = NOMINAL
    """The adversary set-up's name (a column label of the matrix)."""
    adversary_specs: Mapping[str, Any] = field(default_factory=dict)
    """``{adversary agent id: spec}``; adversaries not listed play their no-op."""
    seeds: tuple[int, ...] = (0,)
    """Seeds; each runs `episodes` episodes, episode ``i`` of seed ``s`` resetting with ``s + i``."""
    episodes: int = 1
    """Episodes per seed."""
    tags: Mapping[str, Any] = field(default_factory=dict)
    """Extra scalar columns copied into every row (e.g. ``{"budget": 0.1}``)."""

    def __post_init__(self) -> None:
        from advgame.registry import scenario_spec

        scenario_spec(self.scenario)  # unknown ids fail here, with a "did you mean"
        for name in ("protagonist", "adversary"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ConfigError(f"EvalJob.{name} must be a non-empty name, got {getattr(self, name)!r}.")
        if not isinstance(self.episodes, int) or isinstance(self.episodes, bool) or self.episodes < 1:
            raise ConfigError(f"EvalJob.episodes must be an int >= 1, got {self.episodes!r}.")
        object.__setattr__(self, "seeds", _seeds(self.seeds, self.episodes))
        object.__setattr__(self, "make_kwargs", self._make_kwargs())
        specs = self.protagonist_spec
        for agent, spec in (specs.items() if isinstance(specs, Mapping) else [("", specs)]):
            _check_spec(spec, f"The protagonist_spec{f' of {agent!r}' if agent else ''}")
        if not isinstance(self.adversary_specs, Mapping):
            raise ConfigError(f"adversary_specs must be a dict {{agent: spec}}, got {self.adversary_specs!r}.")
        for agent, spec in self.adversary_specs.items():
            _check_spec(spec, f"The adversary spec of {agent!r}")
        bad = {k: v for k, v in dict(self.tags).items()
               if k in COLUMNS or not isinstance(v, (str, int, float))}
        if bad:
            raise ConfigError(f"tags {bad} must be scalars named apart from the columns {COLUMNS}.")

    def _make_kwargs(self) -> dict[str, Any]:
        if not isinstance(self.make_kwargs, Mapping):
            raise ConfigError(f"make_kwargs must be a dict of advgame.make options, got {self.make_kwargs!r}.")
        kw = {"phase": "eval", **self.make_kwargs}
        if kw["phase"] not in ("train", "eval"):
            raise ConfigError(f"make_kwargs phase must be 'train' or 'eval', got {kw['phase']!r}.")
        if "preset" in kw and "disruptors" in kw:
            raise ConfigError("make_kwargs has both preset= and disruptors=; give one of them.")
        return kw


@contextlib.contextmanager
def _torch_threads(n: int) -> Iterator[None]:
    """Run torch (if this process imported it) on `n` threads, restoring the count after."""
    torch = sys.modules.get("torch")
    before = torch.get_num_threads() if torch is not None else 0
    if torch is not None:
        torch.set_num_threads(n)
    try:
        yield
    finally:
        if torch is not None:
            torch.set_num_threads(before)


def _policies(job: EvalJob, game: Any) -> dict[str, Any]:
    unknown = set(job.adversary_specs) - set(game.adversaries)
    if unknown:
        hint = "".join(did_you_mean(u, game.adversaries) for u in sorted(unknown))
        raise UnknownNameError(
            f"Job {job.protagonist!r} vs {job.adversary!r}: {sorted(unknown)} are not adversaries of "
            f"{job.scenario} made with {job.make_kwargs}.{hint} Its adversaries: {list(game.adversaries)}.")
    specs = job.protagonist_spec
    if isinstance(specs, Mapping):
        if set(specs) != set(game.protagonists):
            raise ConfigError(f"protagonist_spec names {sorted(specs)}, but {job.scenario}'s "
                              f"protagonists are {list(game.protagonists)}; give one spec for each.")
        return {**specs, **job.adversary_specs}
    return {**dict.fromkeys(game.protagonists, specs), **job.adversary_specs}


def run_job(job: EvalJob) -> list[dict[str, Any]]:
    """Play `job` and return one row per episode (`COLUMNS` plus the job's tags).

    Policies are built afresh for every seed, so a seed's rows do not depend on the other
    seeds of the job; torch, if imported, runs on one thread meanwhile.
    """
    import advgame
    from advgame.rollout import build_policies, rollout

    game = advgame.make(job.scenario, **job.make_kwargs)
    rows = []
    try:
        specs = _policies(job, game)
        for seed in job.seeds:
            policies = build_policies(game, specs)
            with _torch_threads(1):
                results = rollout(game, policies, seed=seed, episodes=job.episodes)
            for i, r in enumerate(results):
                rows.append({
                    "scenario": job.scenario, "protagonist": job.protagonist,
                    "adversary": job.adversary, "seed": seed, "episode": i,
                    "true_return": float(r.true_return), "observed_return": float(r.observed_return),
                    "cost": float(r.cost), "payoff": float(r.payoff), "length": int(r.length),
                    "clipped": int(sum(r.clipped.values())), **job.tags})
    finally:
        game.close()
    return rows


def _init_worker(path: list[str]) -> None:
    """Pool initializer: the parent's import path, and one thread for torch and BLAS."""
    sys.path[:] = path + [p for p in sys.path if p not in path]
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"  # read by torch and BLAS when (and if) a job first imports them
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def _run_pickled(blob: bytes) -> list[dict[str, Any]]:
    try:
        job = pickle.loads(blob)
    except Exception as exc:  # a spec or callable that is not importable in a fresh process
        raise ConfigError(
            f"A worker process cannot load a job: {type(exc).__name__}: {exc}. Define callables "
            "and spec classes at module level of an importable module, or use workers=1.") from None
    return run_job(job)


def _pickled(job: EvalJob) -> bytes:
    try:
        return pickle.dumps(job)
    except Exception as exc:
        raise ConfigError(
            f"Job {job.protagonist!r} vs {job.adversary!r} cannot be sent to a worker process "
            f"({type(exc).__name__}: {exc}). Use module-level functions instead of lambdas or "
            "closures, specs instead of live policies, or workers=1.") from None


def evaluate(jobs: Iterable[EvalJob], workers: int = 1, progress: bool = True,
             start_method: str = "forkserver") -> PayoffTable:
    """Run `jobs` and collect their rows, in job order, into a `PayoffTable`.

    Args:
        jobs: the cells to play.
        workers: 1 runs in this process; more runs a `ProcessPoolExecutor` of that many workers.
        progress: show a tqdm bar (on stderr).
        start_method: ``"forkserver"`` or ``"spawn"`` (never fork: simulators and torch hold
            threads and GL contexts that do not survive it).
    """
    from tqdm.auto import tqdm

    jobs = list(jobs)
    if not all(isinstance(j, EvalJob) for j in jobs):
        raise ConfigError("evaluate() takes EvalJob objects; build them with population_jobs().")
    if not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers must be an int >= 1, got {workers!r}.")
    if start_method not in ("forkserver", "spawn"):
        raise ConfigError(f"start_method must be 'forkserver' or 'spawn', got {start_method!r}.")
    out: list[list[dict[str, Any]]] = [[] for _ in jobs]
    log.info("evaluating %d jobs on %d worker(s)", len(jobs), workers)
    with tqdm(total=len(jobs), desc="evaluate", unit="job", file=sys.stderr,
              disable=not progress) as bar:
        if workers == 1 or len(jobs) <= 1:
            for i, job in enumerate(jobs):
                out[i] = run_job(job)
                bar.update()
        else:
            blobs = [_pickled(j) for j in jobs]
            ctx = multiprocessing.get_context(start_method)
            with ProcessPoolExecutor(min(workers, len(jobs)), mp_context=ctx,
                                     initializer=_init_worker, initargs=(list(sys.path),)) as pool:
                futures = {pool.submit(_run_pickled, b): i for i, b in enumerate(blobs)}
                try:
                    for fut in as_completed(futures):
                        out[futures[fut]] = fut.result()
                        bar.update()
                except BaseException:
                    pool.shutdown(wait=False, cancel_futures=True)
                    raise
    return PayoffTable([row for rows in out for row in rows])


# -- the payoff table -----------------------------------------------------------------------
def _parse(key: str, text: str) -> Any:
    if key in _STR:
        return text
    if key in _INT:
        return int(text)
    try:
        return float(text)
    except ValueError:
        return text


class PayoffTable:
    """Episode rows (protagonist × adversary × seed × episode) and the robust metrics on them.

    Args:
        rows: dicts with at least ``protagonist``, ``adversary``, ``seed`` and ``true_return``.

    Example:
        >>> t = PayoffTable([{"protagonist": "p", "adversary": a, "seed": 0, "true_return": r}
        ...                  for a, r in [("nominal", 10.0), ("gauss", 6.0), ("push", 4.0)]])
        >>> m = t.metrics(alpha=0.5)[0]
        >>> m["mean"], m["worst"], m["worst_adversary"], m["degradation"]
        (5.0, 4.0, 'push', 0.5)
    """

    def __init__(self, rows: Iterable[Mapping[str, Any]] = ()) -> None:
        self.rows: list[dict[str, Any]] = [dict(r) for r in rows]
        for r in self.rows:
            missing = {"protagonist", "adversary", "seed", "true_return"} - r.keys()
            if missing:
                raise ConfigError(f"Payoff row {r} lacks columns {sorted(missing)}.")

    def __len__(self) -> int:
        return len(self.rows)

    def __repr__(self) -> str:
        return (f"PayoffTable({len(self.rows)} rows, protagonists={self.protagonists}, "
                f"adversaries={self.adversaries})")

    @property
    def protagonists(self) -> list[str]:
        """Protagonist names in order of first appearance."""
        return list(dict.fromkeys(r["protagonist"] for r in self.rows))

    @property
    def adversaries(self) -> list[str]:
        """Adversary names in order of first appearance."""
        return list(dict.fromkeys(r["adversary"] for r in self.rows))

    def columns(self) -> list[str]:
        """`COLUMNS` present in the rows, then any extra (tag) columns, sorted."""
        keys = dict.fromkeys(k for r in self.rows for k in r)
        return [c for c in COLUMNS if c in keys] + sorted(k for k in keys if k not in COLUMNS)

    def values(self, protagonist: str, adversary: str, column: str = "true_return") -> np.ndarray:
        """`column` of every episode of one cell (empty if the cell was not played)."""
        return np.array([float(r[column]) for r in self.rows
                         if r["protagonist"] == protagonist and r["adversary"] == adversary])

    def seed_means(self, protagonist: str, adversary: str) -> np.ndarray:
        """The cell's mean true return per seed (the samples its interval is computed over)."""
        by_seed: dict[Any, list[float]] = {}
        for r in self.rows:
            if r["protagonist"] == protagonist and r["adversary"] == adversary:
                by_seed.setdefault(r["seed"], []).append(float(r["true_return"]))
        return np.array([np.mean(v) for v in by_seed.values()])

    def matrix(self, stat: str = "mean", column: str = "true_return",
               ) -> tuple[list[str], list[str], np.ndarray]:
        """``(protagonists, adversaries, M)``: `stat` of `column` over each cell's episodes.

        `stat` is ``"mean"``, ``"median"``, ``"std"``, ``"min"`` or ``"max"``; cells not
        played are nan.
        """
        fns = {"mean": np.mean, "median": np.median, "std": np.std, "min": np.min, "max": np.max}
        if stat not in fns:
            raise ConfigError(f"Unknown stat {stat!r}.{did_you_mean(stat, fns)} Known: {sorted(fns)}.")
        ps, adv = self.protagonists, self.adversaries
        m = np.full((len(ps), len(adv)), np.nan)
        for (i, p), (j, a) in itertools.product(enumerate(ps), enumerate(adv)):
            v = self.values(p, a, column)
            if v.size:
                m[i, j] = fns[stat](v)
        return ps, adv, m

    def cells(self) -> list[dict[str, Any]]:
        """Per cell: episodes, seeds, mean, std and 95 % interval half-width over seed means."""
        out = []
        for p, a in itertools.product(self.protagonists, self.adversaries):
            v, s = self.values(p, a), self.seed_means(p, a)
            if v.size:
                out.append({"protagonist": p, "adversary": a, "episodes": v.size, "seeds": s.size,
                            "mean": float(v.mean()), "std": float(s.std(ddof=1)) if s.size > 1 else math.nan,
                            "ci95": ci95(s), "min": float(v.min()), "max": float(v.max())})
        return out

    def metrics(self, alpha: float = 0.1, nominal: str = NOMINAL) -> list[dict[str, Any]]:
        """Robust metrics per protagonist, on the true return.

        ``nominal``: mean in the `nominal` column (nan if absent). Over the other columns:
        ``mean`` of all their episodes, ``worst`` the lowest cell mean (`worst_case`) and
        ``worst_adversary`` its column, ``cvar`` the `cvar` of all their episodes;
        ``degradation``/``worst_degradation`` of mean/worst from nominal (`degradation`);
        ``nominal_ci95``/``worst_ci95`` the interval half-widths over seeds of those cells.
        """
        rows = []
        for p in self.protagonists:
            cells = {a: self.values(p, a) for a in self.adversaries}
            others = {a: v for a, v in cells.items() if v.size and a != nominal}
            nom = float(cells[nominal].mean()) if nominal in cells and cells[nominal].size else math.nan
            pooled = np.concatenate(list(others.values())) if others else np.zeros(0)
            means = {a: float(v.mean()) for a, v in others.items()}
            worst_adv = min(means, key=means.__getitem__) if means else ""
            worst = worst_case(means) if means else math.nan
            mean = float(pooled.mean()) if pooled.size else math.nan
            rows.append({
                "protagonist": p, "nominal": nom, "mean": mean, "worst": worst,
                "worst_adversary": worst_adv, "cvar": cvar(pooled, alpha) if pooled.size else math.nan,
                "degradation": degradation(nom, mean), "worst_degradation": degradation(nom, worst),
                "nominal_ci95": ci95(self.seed_means(p, nominal)),
                "worst_ci95": ci95(self.seed_means(p, worst_adv)) if means else math.nan,
                "adversaries": len(others), "episodes": int(pooled.size)})
        return rows

    def to_csv(self, path: str | Path) -> Path:
        """Write the rows as CSV (`columns` order; missing tags are empty); returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.columns(), restval="")
            writer.writeheader()
            writer.writerows(self.rows)
        return path

    @classmethod
    def from_csv(cls, path: str | Path) -> PayoffTable:
        """Read a table written by `to_csv` (numbers parsed back; empty cells dropped)."""
        with Path(path).open(newline="") as f:
            return cls({k: _parse(k, v) for k, v in r.items() if v != ""} for r in csv.DictReader(f))

    def to_json(self, path: str | Path) -> Path:
        """Write ``{"columns": [...], "rows": [...]}`` as JSON; returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"columns": self.columns(), "rows": self.rows}, indent=1))
        return path

    @classmethod
    def from_json(cls, path: str | Path) -> PayoffTable:
        """Read a table written by `to_json`."""
        return cls(json.loads(Path(path).read_text())["rows"])
