"""Parking: a campaign's runs in training carried from one session to the next.

``parked/`` is kept out of git (replay buffers and half-finished runs do not belong there).

A run resumes from its last checkpoint (``runs/RUN``), but ``runs/`` is not committed: its
checkpoints pile up, and an off-policy learner's is SB3's whole preallocated replay buffer
(200 MB for Hopper, more for Ant) at every iteration. A run longer than the time a machine
is kept (an OMPO run is seven core-hours) would then start over after every interruption.

`park_run` writes what a resume needs, and nothing else, to ``parked/RUN`` beside ``runs/``:
the run's ``config.json``, ``state.json``, ``population.json`` and ``progress.csv``; its last
checkpoint folder (and, where the run samples older opponents, every folder its population
names), without replay buffers; each replay buffer as append-only chunks of its filled rows
(`advgame.agents.common.replay_store`), so parking the run again later adds only what it learned
since. `unpark_run` rebuilds ``runs/RUN`` from it; `advgame.workflows.campaign.run_campaign`
does that by itself for every run whose parked copy is further on than ``runs/`` holds, and
deletes the parked copy once the run is finished (``finished/`` holds it then).

Where: ``parked/`` in the campaign's folder by default, kept out of git, so a fresh checkout
of the repository does not have it. ``ADVGAME_PARK`` (`PARK_ENV`) names a folder outside the
work tree instead: ``--park`` writes ``$ADVGAME_PARK/CAMPAIGN/RUN`` (``CAMPAIGN``: the
campaign folder's name, ``causal-door``), and the train stage looks there and in ``parked/``
and resumes from the copy that is furthest on (`park_root`, `parked_copies`).

A parked run is a consistent snapshot at an iteration boundary: ``state.json`` is written
last and names a checkpoint whose files (and the chunks its replay manifests name) are all
there, so a park interrupted at any point leaves the previous snapshot usable. Its TensorBoard
events are not kept (the curves are in ``progress.csv``).
"""

from __future__ import annotations

import json
import logging
import shutil
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

from advgame.core.config import load_json, read_json, write_atomic
from advgame.errors import ConfigError

__all__ = [
    "PARKED",
    "PARK_ENV",
    "ParkEvery",
    "park_root",
    "park_run",
    "parked_copies",
    "parked_iteration",
    "unpark_run",
]

PARKED = "parked"
"""A campaign's folder of parked runs (beside ``runs/`` and ``finished/``)."""
PARK_ENV = "ADVGAME_PARK"
"""The environment variable naming a folder for parked runs outside the work tree."""

log = logging.getLogger(__name__)


def park_root(out: Path) -> Path:
    """Where ``--park`` writes the parked runs of the campaign in `out`.

    ``$ADVGAME_PARK/NAME`` (``NAME``: `out`'s folder name) when `PARK_ENV` is set, else
    ``out/parked``.
    """
    import os

    folder = os.environ.get(PARK_ENV, "").strip()
    return Path(folder).expanduser() / Path(out).resolve().name if folder else Path(out) / PARKED


def parked_copies(out: Path, run: str) -> list[Path]:
    """The folders a parked copy of `run` may be in: `park_root`'s, then ``out/parked``'s."""
    places = [park_root(out) / run, Path(out) / PARKED / run]
    return list(dict.fromkeys(places))  # one entry when ADVGAME_PARK is not set


_TOP = ("config.json", "population.json", "progress.csv")
"""A run's top-level files a resume reads (``state.json`` is written after them)."""
_REPLAY = "_replay.pkl"
_MANIFEST = "_replay.json"
_KEYS = ("format", "filled", "arrays", "chunks", "buffer")


def parked_iteration(folder: Path) -> int:
    """The iteration the run parked in `folder` resumes after (0: nothing parked there)."""
    if not (folder / "state.json").is_file():
        return 0
    return int(read_json(folder / "state.json", "parked run state", ("iteration",))["iteration"])


def _folders(run: Path, state: dict[str, Any]) -> list[str]:
    """Checkpoint folders (relative to `run`) a resume of `run` reads."""
    from advgame.training.config import TrainConfig
    from advgame.training.population import PATH_FIELDS, Population

    keep = [str(state["checkpoint"])]
    if load_json(TrainConfig, run / "config.json").sampling != "latest":
        for member in Population.load(run / "population.json"):
            for field in PATH_FIELDS:
                value = getattr(member.spec, field, None)
                if value and Path(value).is_relative_to(run.resolve()):
                    folder = str(Path(value).parent.relative_to(run.resolve()))
                    if folder not in keep:
                        keep.append(folder)
    return keep


def _copy_folder(source: Path, target: Path) -> None:
    """Copy a checkpoint folder's files but its replay buffers (a rename puts it in place)."""
    partial = target.with_name(target.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True)
    for path in sorted(source.iterdir()):
        if path.is_file() and not path.name.endswith(_REPLAY):
            shutil.copy2(path, partial / path.name)
    shutil.rmtree(target, ignore_errors=True)
    partial.rename(target)


def _previous_manifest(parked: Path, agent: str) -> dict[str, Any] | None:
    """The replay manifest of `agent` in the checkpoint the parked run resumes from now."""
    if not (parked / "state.json").is_file():
        return None
    state = read_json(parked / "state.json", "parked run state", ("checkpoint",))
    path = parked / state["checkpoint"] / f"{agent}{_MANIFEST}"
    return read_json(path, "replay manifest", _KEYS) if path.is_file() else None


def park_run(run: Path, parked: Path, attempts: int = 3) -> int:
    """Park the run in `run` (training or not) in `parked`; return the iteration parked.

    Safe beside the run's own training: it reads the checkpoint ``state.json`` names, and
    starts again (up to `attempts` times) if the run moves on and deletes a file it was reading.
    """
    for attempt in range(attempts):
        try:
            return _park(Path(run), Path(parked))
        except FileNotFoundError:
            if attempt == attempts - 1:
                raise
    raise AssertionError("unreachable")  # pragma: no cover


def _park(run: Path, parked: Path) -> int:
    from stable_baselines3.common.save_util import load_from_pkl

    from advgame.agents.common.replay_store import store_buffer
    from advgame.training.population import Population

    if not (run / "state.json").is_file():
        raise ConfigError(f"No run state in {run}: nothing to park (train it first).")
    state = read_json(run / "state.json", "run state", ("iteration", "checkpoint"))
    keep = _folders(run, state)
    parked.mkdir(parents=True, exist_ok=True)
    latest = str(state["checkpoint"])
    manifests = {}
    for rel in keep:
        if rel == latest or not (parked / rel).is_dir():
            _copy_folder(run / rel, parked / rel)
    for replay in sorted((run / latest).glob(f"*{_REPLAY}")):
        agent = replay.name[: -len(_REPLAY)]
        previous = _previous_manifest(parked, agent)
        buffer = load_from_pkl(replay)
        manifests[agent] = store_buffer(buffer, parked / "replay" / agent, previous)
        manifest = json.dumps(manifests[agent]) + "\n"
        write_atomic(parked / latest / f"{agent}{_MANIFEST}", manifest)
    for name in _TOP:
        if (run / name).is_file():
            write_atomic(parked / name, (run / name).read_bytes())
    population = Population.load(parked / "population.json")  # paths now under `parked`
    population.drop_missing()
    population.save(parked / "population.json")
    write_atomic(parked / "state.json", (run / "state.json").read_bytes())
    _tidy(parked, keep, manifests)
    return int(state["iteration"])


def _tidy(parked: Path, keep: list[str], manifests: dict[str, dict[str, Any]]) -> None:
    """Delete parked checkpoint folders and replay chunks the new snapshot does not read."""
    wanted = {(parked / rel).resolve() for rel in keep}
    for folder in sorted((parked / "checkpoints").glob("*")):
        if folder.resolve() not in wanted:
            shutil.rmtree(folder)
    for agent_folder in sorted((parked / "replay").glob("*")):
        named = {c["file"] for c in manifests.get(agent_folder.name, {}).get("chunks", [])}
        for chunk in agent_folder.iterdir():
            if chunk.name not in named:
                chunk.unlink()


def unpark_run(parked: Path, run: Path) -> int:
    """Rebuild ``runs/RUN`` (`run`, replaced) from its parked copy; return its iteration.

    Every file comes back as it was parked, and each replay buffer is written again as the
    pickle SB3's resume reads, holding the same transitions bit for bit.
    """
    from stable_baselines3.common.save_util import save_to_pkl

    from advgame.agents.common.replay_store import load_buffer

    parked, run = Path(parked), Path(run)
    iteration = parked_iteration(parked)
    if not iteration:
        raise ConfigError(f"No parked run in {parked} (no state.json).")
    partial = run.with_name(run.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    shutil.copytree(parked, partial, ignore=shutil.ignore_patterns("replay", "*.partial"))
    for manifest in sorted(partial.glob(f"checkpoints/*/*{_MANIFEST}")):
        agent = manifest.name[: -len(_MANIFEST)]
        data = read_json(manifest, "replay manifest", _KEYS)
        buffer = load_buffer(data, parked / "replay" / agent)
        save_to_pkl(manifest.with_name(f"{agent}{_REPLAY}"), buffer)
        manifest.unlink()
    shutil.rmtree(run, ignore_errors=True)
    partial.rename(run)
    return iteration


class ParkEvery:
    """Park the runs a train stage trains every `seconds`, in a thread beside the training.

    A session that ends without ``--park`` (a machine taken back, a process killed) then loses
    at most `seconds` of each run, not everything since the last park: the train stage of
    ``advgame campaign`` runs one while it trains (``--park-every``; every 30 minutes by default
    when `PARK_ENV` is set). `park` is called with no arguments and returns the iteration each
    run was parked at (`advgame.workflows.campaign.park_campaign` over the stage's runs). A
    failed park is logged and tried again at the next tick; the training never sees it. Leaving
    the block by ``KeyboardInterrupt`` parks once more (each run at its last checkpoint) before
    the interrupt goes on.

    Used as a context manager::

        with ParkEvery(lambda: park_campaign(campaign, out, only=runs), 1800):
            ...  # train
    """

    def __init__(self, park: Callable[[], Mapping[str, int]], seconds: float) -> None:
        if not seconds > 0:
            raise ConfigError(f"The time between parks must be > 0 seconds, got {seconds}.")
        self.park, self.seconds = park, float(seconds)
        self.parks = 0
        """How many parks have completed (each a call of `park` that returned)."""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def park_once(self) -> None:
        """Park now; log what was parked, or why parking failed (never raises)."""
        try:
            parked = self.park()
        except Exception as error:  # a run finishing or moving mid-park, a full disk: next tick
            log.warning(
                "campaign: parking failed (%s: %s); trying again later", type(error).__name__, error
            )
            return
        self.parks += 1
        if parked:
            where = ", ".join(f"{run} at iteration {it}" for run, it in parked.items())
            log.info("campaign: parked %s", where)

    def _loop(self) -> None:
        while not self._stop.wait(self.seconds):
            self.park_once()

    def __enter__(self) -> ParkEvery:
        self._thread = threading.Thread(target=self._loop, name="advgame-park", daemon=True)
        self._thread.start()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if kind is not None and issubclass(kind, KeyboardInterrupt):
            self.park_once()
