"""The house: imports point one way, files stay small, moved class paths keep loading.

The import graph is read from the code (every ``import`` statement: at module level, inside
functions and under ``TYPE_CHECKING``), so a new arrow back up fails here, not in review.
"""

from __future__ import annotations

import ast
import collections
import io
import json
import pickle
from pathlib import Path

import pytest

from advgame.core import moved

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"advgame": "advgame", "agents": "advgame.agents", "adversaries": "advgame.adversaries",
           "scenarios": "advgame.scenarios"}  # fmt: skip
"""Repository folder -> the package it is installed as."""

LAYERS = [
    ("advgame.errors",),
    ("advgame.core",),
    (
        "advgame.disruptors",
        "advgame.agents",
        "advgame.adversaries",
        "advgame.scenarios",
        "advgame.interop",
    ),
    ("advgame.training",),
    ("advgame.runner",),
    ("advgame.evaluation",),
    ("advgame.reports",),
    ("advgame.workflows",),
    ("advgame.cli",),
    ("advgame",),  # the package's lazy facade (``advgame.make``, ...) sits on top
]
"""Bottom to top: a module may import its own layer (without a circle) and the ones below."""

MAX_LINES = 400

LAZY = {"__getattr__", "__dir__"}
"""What a package ``__init__`` may define: lazy re-exports (PEP 562), no other logic."""


def _modules() -> dict[str, Path]:
    out = {}
    for folder, package in FOLDERS.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            parts = parts[:-1] if parts[-1] == "__init__" else parts
            out[".".join((package, *parts))] = path
    return out


MODULES = _modules()


def _imports(path: Path) -> set[str]:
    """Every advgame module `path` imports (``from P import m`` counts as P.m when m is one)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [
                f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in MODULES else node.module
                for a in node.names
            ]
        else:
            continue
        found.update(n for n in names if n in MODULES)
    return found


GRAPH = {name: _imports(path) - {name} for name, path in MODULES.items()}


def _layer(module: str) -> int:
    best = -1, -1
    for rank, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if module == prefix or module.startswith(prefix + "."):
                best = max(best, (len(prefix), rank))
    assert best[1] >= 0, f"{module} is in no layer: add its folder to LAYERS"
    return best[1]


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_graph_is_read_from_the_code() -> None:
    # a known arrow of each kind: module level, inside a function, from-import of a module
    assert "advgame.core.game" in GRAPH["advgame.core.registry"]
    assert "advgame.core.disruptor" in GRAPH["advgame.core.game"]
    assert "advgame.workflows.zoo" in GRAPH["advgame.cli.campaign"]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_imports_a_higher_layer() -> None:
    up = sorted(f"{a} -> {b}" for a, bs in GRAPH.items() for b in bs if _layer(b) > _layer(a))
    assert not up, "arrows back up:\n" + "\n".join(up)


def test_no_circle_of_imports() -> None:
    assert not _cycles(GRAPH), _cycles(GRAPH)


def test_no_circle_between_folders() -> None:
    def folder(module: str) -> str:
        parts = module.split(".")
        return ".".join(parts[:2]) if len(parts) > 1 else parts[0]

    folders: dict[str, set[str]] = collections.defaultdict(set)
    for a, bs in GRAPH.items():
        folders[folder(a)].update(folder(b) for b in bs if folder(b) != folder(a))
    folders.pop("advgame", None)  # the facade imports down into every folder by design
    assert not _cycles(folders), _cycles(folders)


AGENT_ROOMS = [
    ("common",),  # what every family shares: replay, normalizers, checkpoints, statistics
    ("sb3",),  # SB3's own PPO/SAC/TD3: the configs the SB3-based families extend
    ("sa", "recurrent", "marl", "safe", "ompo", "rsc", "dbc"),  # one room per learner family
    ("learners", ""),  # the registry of single-agent configs, and the package's face
]
"""Rooms of `advgame.agents`, bottom to top (a room is ``advgame.agents.<room>``)."""
FAMILIES = AGENT_ROOMS[2]

FAMILY_EDGES = {
    ("sa", "recurrent"): "SA-PPO's recurrent form is the unrolled LSTM PPO plus the regulariser: "
    "SARecurrentPPO extends UnrolledRecurrentPPO, its config RecurrentPPOConfig",
    ("safe", "marl"): "the constrained learners are team PPO with a cost critic: they reuse "
    "MAPPO's networks, collector and update (TeamLearner, TeamPPOConfig)",
}
"""The only imports from one family into another, each with its reason."""


def _room(module: str) -> str:
    return module.split(".")[2] if module.count(".") >= 2 else ""


def test_agents_rooms_import_down_and_families_not_each_other() -> None:
    rank = {room: k for k, rooms in enumerate(AGENT_ROOMS) for room in rooms}
    agents = {m for m in MODULES if m.startswith("advgame.agents")}
    assert not {_room(m) for m in agents} - set(rank), "a room of agents/ is in no AGENT_ROOMS"
    bad, used = [], set()
    for a in sorted(agents):
        for b in sorted(GRAPH[a] & agents):
            ra, rb = _room(a), _room(b)
            if ra == rb or rank[rb] < rank[ra] or (rank[rb] == rank[ra] and ra not in FAMILIES):
                continue
            if (ra, rb) in FAMILY_EDGES:
                used.add((ra, rb))
                continue
            bad.append(f"{a} -> {b}")
    assert not bad, "agents/ rooms importing sideways or up (move the shared part down):\n" + (
        "\n".join(bad)
    )
    assert used == set(FAMILY_EDGES), f"allowed edges no longer used: {set(FAMILY_EDGES) - used}"


def test_agents_has_no_flat_file_of_a_family() -> None:
    flat = sorted(m for m in MODULES if m.startswith("advgame.agents.") and m.count(".") == 2
                  and MODULES[m].name != "__init__.py")  # fmt: skip
    assert flat == ["advgame.agents.learners"], f"put each in its family's room: {flat}"


def test_every_file_is_under_the_limit() -> None:
    files = list(MODULES.values())
    long = {
        str(p.relative_to(ROOT)): n
        for p in files
        if (n := len(p.read_text().splitlines())) > MAX_LINES
    }
    assert not long, f"files over {MAX_LINES} lines: {long}"


def test_every_source_folder_is_a_package_and_nothing_in_it_is_ignored() -> None:
    """A fresh clone has every module: each folder has an ``__init__``, no ``.py`` is git-ignored.

    (``advgame/reports/__init__.py`` once matched a ``reports/`` line meant for output folders:
    the checkout had it, a clone did not, and the folder became a namespace package.)
    """
    import shutil
    import subprocess

    folders = {p.parent for p in MODULES.values()}
    bare = sorted(str(f.relative_to(ROOT)) for f in folders if not (f / "__init__.py").exists())
    assert not bare, f"folders without an __init__.py: {bare}"
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    paths = "\n".join(str(p.relative_to(ROOT)) for p in MODULES.values())
    out = subprocess.run(
        ["git", "check-ignore", "--no-index", "--stdin"],
        cwd=ROOT, input=paths, capture_output=True, text=True, check=False,
    )  # fmt: skip
    ignored = out.stdout.split()
    assert not ignored, f"source files a clone would lack (.gitignore matches them): {ignored}"


def test_every_package_is_in_the_distribution() -> None:
    """A wheel holds only the packages pyproject lists: a new room must be listed there."""
    import tomllib

    listed = set(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    packages = {name for name, path in MODULES.items() if path.name == "__init__.py"}
    assert packages <= listed, f"add to [tool.setuptools] packages: {sorted(packages - listed)}"


def test_package_inits_hold_no_logic() -> None:
    """Each folder's ``__init__`` opens with what the folder is for and defines nothing."""
    for name, path in MODULES.items():
        if path.name != "__init__.py" or name == "advgame":  # the facade's lazy __getattr__
            continue
        tree = ast.parse(path.read_text())
        assert ast.get_docstring(tree), f"{path} has no docstring saying what the folder is for"
        defs = [
            n.name
            for n in tree.body
            if isinstance(n, (ast.FunctionDef, ast.ClassDef)) and n.name not in LAZY
        ]
        assert not defs, f"{path} defines {defs}: move the logic into a module of the folder"


# -- moved modules: what files name keeps loading ----------------------------------------
def test_every_moved_module_exists_and_the_old_names_are_gone() -> None:
    for old, new in moved.MOVED.items():
        last, _ = moved.current(new)
        assert last in MODULES, f"MOVED maps {old} to {new}, and {last} does not exist"
        # a module may become a folder of its own name (agents/rsc.py -> agents/rsc/)
        assert old not in MODULES or MODULES[old].name == "__init__.py", (
            f"{old} exists again: drop it from MOVED or rename the module"
        )
    news = list(moved.MOVED.values())
    twice = sorted({n for n in news if news.count(n) > 1})
    assert not twice, f"two old names for one module (`former` must be one): {twice}"


def test_old_agents_names_are_the_new_modules_and_classes() -> None:
    """Every old ``advgame.agents.*`` name imports (SB3 zips unpickle by it) as the new one."""
    import importlib

    from advgame.agents.common import aliases

    names = aliases.old_names()
    assert "advgame.agents.rsc_model" in names and "advgame.agents.checkpoint" in names
    for old, new in names.items():
        module, target = importlib.import_module(old), importlib.import_module(new)
        if old not in MODULES:  # aliased: the very module object
            assert module is target, old
            continue
        for attr in target.__all__:  # now its family's folder: the old module's public names
            new_module, new_attr = moved.current(old, attr)
            found = getattr(importlib.import_module(new_module), new_attr or attr)
            assert found is getattr(target, attr), f"{old}.{attr}"
            if (old, attr) not in moved.MOVED_NAMES:
                assert getattr(module, attr) is found, f"{old}.{attr}"


RELEASED = {  # zoo entry -> algo: each zip's data pickles classes under old agents names
    "hopper/sa-ppo": "ppo",  # advgame.agents.sb3.LinearDecay (the learning-rate schedule)
    "hopper-ompo/ompo": "ompo",  # advgame.agents.ompo_nets.OMPOPolicy, .ompo.OMPOReplayBuffer
    "rs-liftcausal/dbc": "dbc",  # advgame.agents.dbc_nets.DBCPolicy
    "rs-liftcausal/rsc": "rsc",  # none (SB3's SACPolicy): it loads through RSC's new module
}


@pytest.mark.parametrize("entry", sorted(RELEASED))
def test_released_zips_load_after_the_agents_moved(entry: str) -> None:
    """SB3 unpickles a zip's classes with plain pickle, by the module names written then."""
    import base64
    import zipfile

    from advgame.agents.common.checkpoint import load_model

    path = ROOT / "zoo" / entry / "protagonist.zip"
    if not path.is_file():
        pytest.skip(f"{path} is not in this checkout")
    with zipfile.ZipFile(path) as archive:
        data = json.loads(archive.read("data"))
    old = {
        key: pickle.loads(blob)  # what SB3's load does: no advgame reader in between
        for key, value in data.items()
        if isinstance(value, dict) and ":serialized:" in value
        and b"advgame.agents." in (blob := base64.b64decode(value[":serialized:"]))
    }  # fmt: skip
    assert old or entry.endswith("/rsc"), f"{entry} names no advgame.agents class"
    named = [v if isinstance(v, type) else type(v) for v in old.values()]
    named = [cls for cls in named if cls.__module__.startswith("advgame.")]
    assert all(cls.__module__ in MODULES for cls in named), named  # found at today's place
    model = load_model(str(path), RELEASED[entry])
    if "policy_class" in old:
        assert type(model.policy) is old["policy_class"]


def test_population_files_name_their_specs_by_old_paths_and_load() -> None:
    from advgame.core.registry import load
    from advgame.training.population import Population

    files = sorted((ROOT / "zoo").glob("*/finished/*/population.json"))
    if not files:
        pytest.skip("no committed campaign populations in this checkout")
    written = {f: json.loads(f.read_text()) for f in files}
    types = {m["spec"]["type"] for members in written.values() for m in members}
    assert any(t.split(":")[0] in moved.MOVED for t in types)  # written before the move
    for t in types:
        assert load(t) is not None
    # A protagonist-only run (SAC, RSC, DBC) writes an empty population: every file loads
    # whole, and at least one holds members.
    loaded = {f: Population.load(f) for f in files}
    for f, pop in loaded.items():
        assert len(pop.members) == len(written[f]), f
    assert any(pop.members for pop in loaded.values())


def test_committed_part_files_load() -> None:
    from advgame.runner.units import UnitRecord, read_part

    parts = sorted((ROOT / "zoo").glob("*/results/parts/*.pkl"))
    if not parts:
        pytest.skip("no committed part files in this checkout")
    old = next(p for p in parts if b"advgame.evaluation.units" in p.read_bytes())
    for path in (old, parts[0]):  # one written before the runner moved, and any other
        rec = read_part(path.parent, path.stem)
        assert isinstance(rec, UnitRecord) and rec.key == path.stem


def test_stable_pickle_writes_old_names_and_matches_the_c_pickler() -> None:
    from advgame.agents.common.checkpoint import SB3Checkpoint
    from advgame.core.game import Game
    from advgame.evaluation.table.jobs import AdversarySetup

    unit = ({"a": (1, 2.5, "x"), "b": [None, True]}, Game, AdversarySetup.nominal(),
            SB3Checkpoint("m.zip", "ppo", None))  # fmt: skip
    blob = moved.stable_pickle(unit)
    assert b"advgame.evaluation.jobs" in blob and b"advgame.training.checkpoint" in blob
    assert b"advgame.evaluation.table" not in blob
    # where no class moved, the bytes are exactly the C pickler's without a memo
    plain = ({"a": (1, 2.5, "x"), "b": [None, True]}, Game)
    buf = io.BytesIO()
    fast = pickle.Pickler(buf, protocol=pickle.HIGHEST_PROTOCOL)
    fast.fast = True
    fast.dump(plain)
    assert moved.stable_pickle(plain) == buf.getvalue()
    # and what it wrote loads back, old names resolved
    back = moved.load_pickle(io.BytesIO(blob))
    assert back[2] == AdversarySetup.nominal() and back[3].path == "m.zip"


def test_a_committed_campaign_finds_its_part_files_by_the_keys_of_its_units(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The Hopper campaign's optimal-attack units, built now, are named as before the move.

    Their pickles spell `BestResponseJob` and `SB3Checkpoint`, whose modules moved
    (`advgame.training.checkpoint` -> `advgame.agents.common.checkpoint`): the keys must not.
    """
    from advgame.core.registry import make
    from advgame.evaluation.attacks.optimal import OPTIMAL_GRID
    from advgame.evaluation.table.protagonists import run_protagonist
    from advgame.runner.parts import has_part
    from advgame.training.best_response import BestResponseJob, MixtureSpec
    from advgame.workflows.suite import observation_agent

    parts = ROOT / "zoo" / "hopper" / "results" / "optimal" / "parts"
    if not parts.is_dir():
        pytest.skip("the Hopper campaign's evaluation is not in this checkout")
    monkeypatch.chdir(ROOT)  # the campaign ran from the repository root: relative paths
    _, spec = run_protagonist(Path("zoo/hopper/finished/ppo-s0"))
    game = make("Hopper-v5", preset="atla")
    opponents = {a: MixtureSpec((spec,), (1.0,)) for a in game.protagonists}
    game.close()
    agent = observation_agent("Hopper-v5", "atla")
    for k, hparams in enumerate(OPTIMAL_GRID[:4]):  # the entries that campaign searched
        unit = BestResponseJob(
            name=f"ppo-s0/{k}", scenario="Hopper-v5", make_kwargs={"preset": "atla"},
            agent=agent, hparams=dict(hparams), opponents=opponents, steps=200_000, seed=k,
        )  # fmt: skip
        assert has_part(parts, unit), k


def test_a_released_agent_loads_and_plays(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from advgame.core.episodes import rollout
    from advgame.core.registry import make
    from advgame.workflows import zoo

    if not (ROOT / "zoo" / "manifest.json").is_file():
        pytest.skip("no zoo in this checkout")
    monkeypatch.delenv("ADVGAME_ZOO", raising=False)
    monkeypatch.chdir(tmp_path)  # the checkout's zoo is found from anywhere, not through ./zoo
    assert zoo.default_root() == ROOT / "zoo"
    spec = zoo.load("hopper/ppo")
    game = make("Hopper-v5")
    (result,) = rollout(game, dict.fromkeys(game.protagonists, spec), seed=0)
    game.close()
    # the released gait (an unloaded or untrained policy falls within ~100 steps, under 1,000);
    # the released PPO since 27 Nov (ppo-s2, 2,813 nominal) hops 772 steps of seed 0
    assert result.true_return > 2_000 and result.length > 500
