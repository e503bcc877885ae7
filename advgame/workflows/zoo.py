"""The zoo: released agents of finished campaigns, each with its files' checksums.

A zoo is a folder with ``manifest.json`` and one folder per entry (``hopper/ppo/``): the
campaign's median agent of a method (by worst-of-adversaries return), its observation
normalizer, and its strongest learned adversary when it has one. The manifest records, per
entry, the scenario, method, training steps and seed, the run's config, the natural and worst
returns with the worst adversary (an attack or a preset: ``worst_attack``) and threat model,
and the sha256 of every file; `load` checks them.

The zoo is found (`default_root`) in ``$ADVGAME_ZOO``, else in the installed ``advgame-zoo``
package (``pip install "advgame[zoo]"``: the released agents as data, built from the
repository's ``zoo/`` by ``zoo/package/build.py``), else in the source checkout's ``zoo/``.
Where none is found, every zoo path says so and how to install it (`missing`)::

    advgame zoo list
    advgame evaluate --zoo hopper/ppo --adversaries attacks --out results/zoo
    spec = advgame.workflows.zoo.load("hopper/ppo")       # an SB3Checkpoint spec, played like any other
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from advgame.core.config import read_json, write_atomic
from advgame.errors import ConfigError, FileFormatError, UnknownNameError, did_you_mean

if TYPE_CHECKING:
    from advgame.workflows.campaign import Campaign

__all__ = [
    "ZooEntry",
    "default_root",
    "entries",
    "entry",
    "load",
    "missing",
    "release",
    "release_campaign",
    "released_adversaries",
    "verify",
]

MANIFEST = "manifest.json"


INSTALL = 'pip install "advgame[zoo]"'
"""The one command that installs the released agents (the ``advgame-zoo`` package)."""


def default_root() -> Path:
    """``$ADVGAME_ZOO``, else the installed ``advgame-zoo`` package, else the checkout's ``zoo/``.

    Outside a checkout and without the package, ``./zoo`` (which `missing` then reports).
    """
    env = os.environ.get("ADVGAME_ZOO")
    if env:
        return Path(env)
    package = importlib.util.find_spec("advgame_zoo")
    if package is not None and package.origin is not None:
        return Path(package.origin).parent
    checkout = Path(__file__).resolve().parents[2] / "zoo"  # advgame/workflows/zoo.py
    return checkout if checkout.is_dir() else Path("zoo")


@dataclass(frozen=True)
class ZooEntry:
    """One released agent (a manifest entry)."""

    id: str
    """``ENV/NAME``, e.g. ``"hopper/ppo"`` (NAME: the campaign's method, or its variant's name)."""
    scenario: str
    """The scenario it was trained and evaluated on."""
    method: str
    """The training method (`advgame.training.METHODS`)."""
    steps: int
    """Protagonist environment steps of its training."""
    seed: int
    """Its training seed."""
    natural_return: float
    """Mean true return, nominal, in its campaign's evaluation."""
    worst_attack_return: float
    """Mean true return under the strongest attack of that evaluation."""
    worst_attack: str
    """That attack's column."""
    threat: str
    """The threat model (preset) the attacks played in; empty where the evaluation played
    none (every column a preset of its own, such as OMPO's shifted bodies)."""
    algo: str = "ppo"
    """The SB3 algorithm of the protagonist file, or the constrained/team learner
    (`advgame.training.TEAM_ALGOS`) whose actors file (with its normalizers) it is."""
    files: dict[str, dict[str, str]] = field(default_factory=dict)
    """``{"protagonist" | "normalizer" | "adversary": {"path": relative path, "sha256": hex}}``."""
    config: dict[str, Any] = field(default_factory=dict)
    """The run's `TrainConfig` as saved."""


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def missing(root: str | Path | None = None) -> str | None:
    """Why the zoo at `root` (default `default_root`) has no agents, with the fix; None if it has."""
    root = Path(root) if root is not None else default_root()
    if (root / MANIFEST).exists():
        return None
    return (
        f"no zoo at {root} (no {MANIFEST}): the released agents come in the advgame-zoo "
        f"package; install them with: {INSTALL} (or set ADVGAME_ZOO to a zoo folder)"
    )


def entries(root: str | Path | None = None) -> list[ZooEntry]:
    """The entries of the zoo at `root` (default `default_root`); none if it has no manifest."""
    root = Path(root) if root is not None else default_root()
    if not (root / MANIFEST).exists():
        return []
    data = read_json(root / MANIFEST, "zoo manifest", ("entries",))
    try:
        return [ZooEntry(**e) for e in data["entries"]]
    except TypeError as exc:
        raise FileFormatError(
            f"The zoo manifest {root / MANIFEST} has an entry of another version ({exc})."
        ) from None


def entry(entry_id: str, root: str | Path | None = None) -> ZooEntry:
    """The manifest entry `entry_id` of the zoo at `root` (default `default_root`)."""
    return _entry(entry_id, Path(root) if root is not None else default_root())


def _entry(entry_id: str, root: Path) -> ZooEntry:
    why = missing(root)
    if why is not None:
        raise ConfigError(f"Zoo agent {entry_id!r}: {why}.")
    found = {e.id: e for e in entries(root)}
    if entry_id not in found:
        raise UnknownNameError(
            f"The zoo at {root} has no agent {entry_id!r}.{did_you_mean(entry_id, found)} "
            f"Agents: {sorted(found) or 'none (advgame zoo list)'}."
        )
    return found[entry_id]


def verify(entry: ZooEntry, root: Path) -> None:
    """Raise `FileFormatError` unless every file of `entry` exists with its recorded sha256."""
    for role, f in entry.files.items():
        path = root / f["path"]
        if not path.is_file():
            raise FileFormatError(f"Zoo agent {entry.id!r}: its {role} file {path} is missing.")
        if _sha256(path) != f["sha256"]:
            raise FileFormatError(
                f"Zoo agent {entry.id!r}: {path} does not match its sha256 in the manifest "
                f"(changed, truncated or from another release); restore it from the repository "
                f"or reinstall the zoo ({INSTALL} --force-reinstall)."
            )


def load(entry_id: str, root: str | Path | None = None, *, adversary: bool = False) -> Any:
    """The released protagonist `entry_id` as a policy spec (or its strongest adversary).

    A constrained or team learner's agent is ``{protagonist id: spec}``, as
    `advgame.evaluation.run_protagonist` gives it. The files are checked against the
    manifest's sha256 first.
    """
    from advgame.agents.common.checkpoint import SB3Checkpoint, saved_recurrent
    from advgame.training import TEAM_ALGOS

    base = Path(root) if root is not None else default_root()
    entry = _entry(entry_id, base)
    verify(entry, base)
    if adversary:
        if "adversary" not in entry.files:
            raise UnknownNameError(f"Zoo agent {entry_id!r} was released without an adversary.")
        f = entry.files["adversary"]
        norm = entry.files.get("adversary_normalizer")
        path = str(base / f["path"])  # a PPO adversary, or an LSTM one (ATLA-LSTM's, issue 40)
        algo = "recurrent-ppo" if saved_recurrent(path) else "ppo"
        return SB3Checkpoint(path, algo, str(base / norm["path"]) if norm else None)
    if entry.algo in TEAM_ALGOS:
        from advgame.evaluation.table.protagonists import team_protagonist

        return team_protagonist(entry.scenario, base / entry.files["protagonist"]["path"])
    norm = entry.files.get("normalizer")
    return SB3Checkpoint(
        str(base / entry.files["protagonist"]["path"]),
        entry.algo,
        str(base / norm["path"]) if norm else None,
        deterministic=True,
    )


def released_adversaries(
    released: Sequence[ZooEntry], threat: str | None, root: str | Path | None = None
) -> dict[str, Any]:
    """``{id: spec}`` of each released agent's adversary, checked to fit one table.

    `threat` is the table's threat model, if given: every agent's must be the same one.
    See `evaluation_inputs`.
    """
    if not released:
        raise ConfigError("--zoo-adversaries needs zoo agents (--zoo ID; advgame zoo list).")
    threats = {e.threat for e in released} | ({threat} if threat else set())
    if len(threats) > 1:
        raise ConfigError(
            f"The zoo agents' adversaries were trained in threat models {sorted(threats)}; "
            "a table has one (--threat): evaluate them apart."
        )
    return {e.id: load(e.id, root, adversary=True) for e in released}


def evaluation_inputs(
    ids: Sequence[str],
    *,
    adversaries: bool = False,
    threat: str | None = None,
    root: str | Path | None = None,
) -> tuple[dict[str, tuple[str, Any]], dict[str, Any] | None, str | None]:
    """What `advgame.workflows.suite.evaluate_runs` needs to play the zoo agents `ids`.

    Returns ``{id: (scenario, protagonist spec)}``, each agent's released adversary
    (``{id: spec}``, only if `adversaries`; None otherwise) and the table's threat model (the
    agents' own when `adversaries` and no `threat` is given).
    """
    found = {z: (entry(z, root), load(z, root)) for z in ids}
    own = None
    if adversaries:
        entries = [e for e, _ in found.values()]
        own = released_adversaries(entries, threat, root)
        threat = threat or entries[0].threat
    return {z: (e.scenario, spec) for z, (e, spec) in found.items()}, own, threat


def release(entry: ZooEntry, sources: dict[str, Path], root: str | Path | None = None) -> ZooEntry:
    """Copy `sources` (``{role: file}``) into the zoo under ``entry.id`` and record them.

    Returns the entry with its files' relative paths and sha256; the manifest is rewritten
    atomically (an entry of the same id is replaced).
    """
    base = Path(root) if root is not None else default_root()
    folder = base / entry.id
    folder.mkdir(parents=True, exist_ok=True)
    files = {}
    for role, src in sources.items():
        dst = folder / f"{role}{''.join(Path(src).suffixes)}"
        shutil.copyfile(src, dst)
        files[role] = {"path": dst.relative_to(base).as_posix(), "sha256": _sha256(dst)}
    done = ZooEntry(**{**asdict(entry), "files": files})
    others = [asdict(e) for e in entries(base) if e.id != entry.id]
    data = {"entries": sorted([*others, asdict(done)], key=lambda e: e["id"])}
    write_atomic(base / MANIFEST, json.dumps(data, indent=2) + "\n")
    return done


def release_campaign(
    campaign: Campaign, out: str | Path, root: str | Path | None = None
) -> list[Any]:
    """Copy each method's median agent (and strongest adversary) into the zoo; return entries.

    The median agent is the one `campaign_table` names; its adversary is the searched optimal
    attack kept for it (``results/optimal.json``) when the campaign searched one.
    """
    import csv

    from advgame.evaluation import run_protagonist
    from advgame.workflows.campaign_status import run_dir

    out = Path(out)
    table = out / "campaign.csv"
    if not table.exists():
        raise FileFormatError(f"{table} is missing; run the campaign to its table first.")
    with table.open(newline="") as f:
        rows = list(csv.DictReader(f))
    optimal_path = out / "results" / "optimal.json"
    optimal = read_json(optimal_path, "optimal-attack search") if optimal_path.exists() else {}
    env = campaign.zoo or campaign.scenario.split("-v")[0].lower()
    threat_path = out / "results" / "threat.json"  # absent: no column played a threat model
    threat = read_json(threat_path, "threat model")["preset"] if threat_path.exists() else ""
    released = []
    for row in rows:
        run = run_dir(out, row["median_agent"])
        cfg, spec = run_protagonist(run)
        if isinstance(spec, dict):  # a constrained or team learner: one actors file for all
            sources = {"protagonist": Path(next(iter(spec.values())).path)}
            algo = cfg.protagonist_algo
        else:
            sources = {"protagonist": Path(spec.path)}
            if spec.normalizer:
                sources["normalizer"] = Path(spec.normalizer)
            algo = spec.algo
        sources.update(_strongest_adversary(run, optimal.get(row["median_agent"], {})))
        entry = ZooEntry(
            id=f"{env}/{row['method']}", scenario=campaign.scenario,
            method=campaign.base_method(row["method"]),
            steps=cfg.protagonist_steps * cfg.iterations + cfg.warmup_steps, seed=cfg.seed,
            natural_return=float(row["natural"]), worst_attack_return=float(row["worst"]),
            worst_attack=row["worst_attack"], threat=threat,
            algo=algo, config=read_json(run / "config.json", "run config"),
        )  # fmt: skip
        released.append(release(entry, sources, root))
    return released


def _strongest_adversary(run: Path, searched: Mapping[str, Any]) -> dict[str, Path]:
    """The files of a run's strongest adversary (none for a run without one).

    That is the optimal attack kept for it, else the run's own last learned observation
    adversary.
    """
    if searched.get("kept"):
        found = {"adversary": Path(searched["kept"])}
        if searched.get("kept_normalizer"):
            found["adversary_normalizer"] = Path(searched["kept_normalizer"])
        return found
    state = read_json(run / "state.json", "run state", ("checkpoint",))
    folder = run / state["checkpoint"]
    model = folder / "observation_adversary.zip"
    if not model.exists():
        return {}
    found = {"adversary": model}
    if (folder / "observation_adversary_obs_norm.npz").exists():
        found["adversary_normalizer"] = folder / "observation_adversary_obs_norm.npz"
    return found
