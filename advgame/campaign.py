"""Campaigns: a grid of methods × seeds trained, evaluated in one threat model, and tabled.

A campaign file (TOML) names a scenario, the methods (`advgame.training.METHODS`) and seeds,
the training budget shared by every run and per method, and the evaluation (columns, seeds,
the threat model, the optimal attack's budget)::

    scenario = "Hopper-v5"
    methods = ["ppo", "atla"]
    seeds = [0, 1, 2]

    [train]                    # TrainConfig fields for every run
    iterations = 976
    protagonist_steps = 2048

    [train.atla]               # and for one method
    adversary_steps = 2048

A name in ``methods`` may also be a variant of a method: its section says which method it
varies, and the rest of the section is the variation (a training preset, hyper-parameters)::

    methods = ["crpo", "crpo-noisy"]

    [train.crpo-noisy]
    method = "crpo"
    preset = "action-gauss-0.3"

    [evaluate]
    adversaries = ["attacks"]  # column specs (advgame.evaluation.columns)
    threat = "atla"
    seeds = 10
    exploitability = 0         # steps of the searched optimal attack (0: none)
    cost_limit = 25            # safe scenarios: add the cost table (episode cost ≤ limit)

`run_campaign` trains every run that is not finished, two (``workers``) at a time as jobs on
the executor (a local process pool or Ray); a run that was interrupted resumes from its last
iteration (``runs/``), a finished one is compacted to its last checkpoint and moved to
``finished/`` in one rename (small enough to commit; never trained again). It then evaluates every finished run's
final protagonist in one table (finished evaluation units are read back, not replayed) and
writes ``campaign.md`` / ``campaign.csv``: per method, the median agent by worst-of-attacks
return, the interquartile range and the 95 % interval over seeds of its natural and
worst-of-attacks returns; with a ``cost_limit`` (safe scenarios), per method and column the
return and episode cost (means over seeds with 95 % intervals) and the share of evaluation
episodes whose cost stays within the limit. ``status.json`` says at every step what is done.
"""

from __future__ import annotations

import json
import logging
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from advgame.campaign_report import campaign_table
from advgame.core.config import read_json, write_atomic
from advgame.errors import ConfigError

__all__ = ["Campaign", "campaign_table", "load_campaign", "run_campaign"]

log = logging.getLogger(__name__)

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
    """Training seeds of every method."""
    train: Mapping[str, Any] = field(default_factory=dict)
    """`TrainConfig` fields for every run."""
    per_method: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    """`TrainConfig` fields for the runs of one method (over `train`); a variant's also names
    its ``method``."""
    adversaries: tuple[str, ...] = ("attacks",)
    """Evaluation column specs."""
    threat: str | None = None
    """The table's threat model (None: `advgame.evaluation.columns.default_threat`)."""
    eval_seeds: int = 5
    """Evaluation seeds per cell."""
    exploitability: int = 0
    """Steps of each candidate of the searched optimal attack (0: no optimal column)."""
    cost_limit: float | None = None
    """Episode cost limit of a safe campaign: adds the cost table (None: no cost table)."""

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
        if not self.seeds or not all(type(s) is int and s >= 0 for s in self.seeds):
            raise ConfigError(f"Campaign seeds must be ints >= 0, got {list(self.seeds)!r}.")
        stray = set(self.per_method) - set(self.methods)
        if stray:
            raise ConfigError(f"[train.{sorted(stray)[0]}] names no method of the campaign.")
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
        for name in self.runs():  # every TrainConfig is checked before anything runs
            self.config(name)

    def base_method(self, method: str) -> str:
        """The `advgame.training.METHODS` name `method` trains with (itself, or its variant's)."""
        return str(self.per_method.get(method, {}).get("method", method))

    def runs(self) -> list[str]:
        """Run names, ``METHOD-sSEED``, method by method."""
        return [f"{m}-s{s}" for m in self.methods for s in self.seeds]

    def method_runs(self, method: str) -> list[str]:
        """The runs of one method (``atla`` is not ``atla-sa``)."""
        return [r for r in self.runs() if r.rpartition("-s")[0] == method]

    def config(self, run: str) -> Any:
        """The `TrainConfig` of run ``METHOD-sSEED``."""
        from advgame.training import METHODS, TrainConfig

        method, _, seed = run.rpartition("-s")
        own = {k: v for k, v in self.per_method.get(method, {}).items() if k != "method"}
        fields = {**METHODS[self.base_method(method)], **self.train, **own}
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
    known = {"scenario", "methods", "seeds", "train", "evaluate"}
    if set(data) - known:
        raise ConfigError(f"{path}: unknown keys {sorted(set(data) - known)}; use {sorted(known)}.")
    train = dict(data.get("train", {}))
    methods = tuple(data.get("methods", ()))
    per_method = {
        m: train.pop(m) for m in list(train) if isinstance(train[m], dict) and m in methods
    }
    ev = dict(data.get("evaluate", {}))
    unknown = set(ev) - {"adversaries", "threat", "seeds", "exploitability", "cost_limit"}
    if unknown:
        raise ConfigError(f"{path}: unknown [evaluate] keys {sorted(unknown)}.")
    return Campaign(
        scenario=str(data.get("scenario", "")),
        methods=methods,
        seeds=tuple(data.get("seeds", (0,))),
        train=train,
        per_method=per_method,
        adversaries=tuple(ev.get("adversaries", ("attacks",))),
        threat=ev.get("threat"),
        eval_seeds=ev.get("seeds", 5),
        exploitability=ev.get("exploitability", 0),
        cost_limit=ev.get("cost_limit"),
    )


def _progress(run_dir: Path) -> int:
    """The last finished iteration of a run (0: none)."""
    if not (run_dir / "state.json").exists():
        return 0
    return int(read_json(run_dir / "state.json", "run state", ("iteration",))["iteration"])


class _StatusEach:
    """Rewrites ``status.json`` each time a run finishes (the executor's progress hook)."""

    def __init__(self, campaign: Campaign, out: Path, training: Sequence[str]) -> None:
        self.campaign, self.out, self.training = campaign, out, training

    def update(self) -> None:
        """One more unit finished: record what is on disk now."""
        write_status(self.campaign, self.out, training=self.training)


def _train_unit(unit: tuple[Any, str, str]) -> str:
    """Train or resume one run to its end, then keep it compact in ``finished/`` (a worker)."""
    from advgame.training import resume, train

    config, partial, finished = unit
    path = Path(partial)
    if (path / "config.json").exists():
        resume(path, progress=False)
    else:
        train(config, path, progress=False)
    compact(path)
    Path(finished).parent.mkdir(parents=True, exist_ok=True)
    path.rename(finished)  # one rename: ``finished/`` never holds half a run
    return finished


FINISHED = "finished"
"""The campaign's folder of finished, compacted runs (``runs/`` holds those in training)."""


def run_dir(out: Path, run: str) -> Path:
    """Where run `run` of the campaign in `out` is: ``finished/RUN`` once done, else ``runs/RUN``."""
    done = out / FINISHED / run
    return done if done.exists() else out / "runs" / run


def compact(run: Path) -> None:
    """Keep what a finished run is evaluated and released from: its last checkpoint.

    Earlier checkpoint folders and TensorBoard logs are deleted and the population keeps the
    members whose files remain, so a finished run is a few hundred KB that can be committed
    (``config.json``, ``state.json``, ``population.json``, ``progress.csv``, the last
    checkpoint).
    """
    import shutil

    from advgame.training.population import Population

    state = read_json(run / "state.json", "run state", ("checkpoint",))
    last = (run / state["checkpoint"]).resolve()
    for folder in (run / "checkpoints").iterdir():
        if folder.resolve() != last:
            shutil.rmtree(folder)
    shutil.rmtree(run / "tb", ignore_errors=True)
    population = Population.load(run / "population.json")
    population.members = [m for m in population if _files_exist(m.spec)]
    population.save(run / "population.json")


def _files_exist(spec: Any) -> bool:
    return all(Path(getattr(spec, f)).exists() for f in ("path",) if getattr(spec, f, None))


def run_campaign(
    campaign: Campaign,
    out: str | Path,
    *,
    workers: int = 2,
    executor: str = "local",
    address: str | None = None,
    stage: str = "all",
    max_runs: int | None = None,
    progress: bool = True,
    only: Sequence[str] | None = None,
) -> Path:
    """Train what is not finished, evaluate, write the table; return ``campaign.md``.

    Args:
        campaign: the grid.
        out: its folder (``runs/``, ``results/``, ``status.json``, ``campaign.md``).
        workers: training runs at once (local pool) or in flight (Ray); also the evaluation's.
        executor: ``"local"`` or ``"ray"``.
        address: a Ray cluster address.
        stage: ``"train"``, ``"evaluate"`` (finished runs only) or ``"all"``.
        max_runs: train at most this many unfinished runs now (the rest another time).
        progress: progress bars for the evaluation.
        only: train only these runs (``METHOD-sSEED``), in this order: how a session picks the
            pieces that fit its time.

    """
    from advgame.evaluation.executor import run_units

    if stage not in ("train", "evaluate", "all"):
        raise ConfigError(f"stage must be 'train', 'evaluate' or 'all', got {stage!r}.")
    out = Path(out)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    if stage in ("train", "all"):
        names = campaign.runs() if only is None else list(only)
        unknown = sorted(set(names) - set(campaign.runs()))
        if unknown:
            raise ConfigError(
                f"No run {unknown[0]!r} in the campaign; its runs: {', '.join(campaign.runs())}."
            )
        todo = [r for r in names if _progress(run_dir(out, r)) < campaign.config(r).iterations]
        todo = todo[:max_runs] if max_runs is not None else todo
        write_status(campaign, out, training=todo)
        if todo:
            log.info("campaign: training %d run(s): %s", len(todo), todo)
            units = [
                (campaign.config(r), str(out / "runs" / r), str(out / FINISHED / r)) for r in todo
            ]
            run_units(_train_unit, units, executor=executor, workers=min(workers, len(units)),
                      address=address, max_retries=1,
                      progress=_StatusEach(campaign, out, todo))  # fmt: skip
    status = write_status(campaign, out)
    if stage == "train":
        return out / "status.json"
    done = [r for r, s in status["runs"].items() if s["state"] == "done"]
    if not done:
        raise ConfigError(f"No finished run in {out / 'runs'} to evaluate; train first.")
    _evaluate(campaign, out, done, workers, executor, address, progress)
    path = campaign_table(campaign, out)
    write_status(campaign, out)
    return path


def _evaluate(
    campaign: Campaign,
    out: Path,
    done: Sequence[str],
    workers: int,
    executor: str,
    address: str | None,
    progress: bool,
) -> None:
    """Every finished run's protagonist in one table (finished units are read back)."""
    from advgame.evaluation import use_executor
    from advgame.evaluation.suite import evaluate_runs

    with use_executor(executor, address):
        evaluate_runs(
            [run_dir(out, r) for r in done],
            out / "results",
            seeds=campaign.eval_seeds,
            workers=workers,
            exploitability_steps=campaign.exploitability,
            adversaries=campaign.adversaries,
            threat=campaign.threat,
            budgets=(),
            progress=progress,
            resume=True,
        )


def write_status(campaign: Campaign, out: Path, training: Sequence[str] = ()) -> dict[str, Any]:
    """Write ``status.json``: each run's state and iteration, and the evaluation's."""
    runs = {}
    for r in campaign.runs():
        it, of = _progress(run_dir(out, r)), campaign.config(r).iterations
        state = (
            "done"
            if it >= of
            else ("training" if r in training else "partial" if it else "pending")
        )
        runs[r] = {"state": state, "iteration": it, "of": of}
    table = out / "campaign.md"
    status = {
        "scenario": campaign.scenario,
        "runs": runs,
        "evaluated": sorted(_evaluated(out)),
        "table": table.name if table.exists() else None,
    }
    write_atomic(out / "status.json", json.dumps(status, indent=2) + "\n")
    return status


def _evaluated(out: Path) -> set[str]:
    """Runs that have rows in the campaign's payoff table."""
    path = out / "results" / "payoff.csv"
    if not path.exists():
        return set()
    from advgame.evaluation import PayoffTable

    return set(PayoffTable.from_csv(path).protagonists)
