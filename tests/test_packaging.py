"""Packaging: the user folders live in the `advgame` namespace; `import advgame` stays light."""

from __future__ import annotations

import importlib
import importlib.metadata
import json
import subprocess
import sys
from pathlib import Path

import pytest

import advgame

ROOT = Path(advgame.__file__).resolve().parents[1]
FOLDERS = ("agents", "adversaries", "scenarios")
HEAVY = ("torch", "mujoco", "gymnasium", "pettingzoo", "robosuite")


def _python(code: str, cwd: Path) -> dict:
    """Run `code` in a fresh interpreter; it prints one JSON object as its last line."""
    proc = subprocess.run(
        [sys.executable, "-c", code],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_repo_root_holds_the_user_folders() -> None:
    for name in (*FOLDERS, "advgame"):
        assert (ROOT / name / "__init__.py").is_file(), name


@pytest.mark.parametrize("name", FOLDERS)
def test_folders_import_inside_the_namespace(name: str) -> None:
    module = importlib.import_module(f"advgame.{name}")
    assert module.__name__ == f"advgame.{name}"
    assert Path(module.__file__).resolve() == ROOT / name / "__init__.py"


def test_namespaced_packages_provide_their_contents() -> None:
    from advgame.adversaries import GaussianAdversary
    from advgame.scenarios import mujoco

    assert GaussianAdversary.__module__ == "advgame.adversaries.noise"
    assert mujoco.__name__ == "advgame.scenarios.mujoco"
    assert "Hopper-v5" in advgame.list_scenarios()


@pytest.mark.parametrize("name", FOLDERS)
def test_bare_folder_name_refuses_to_import(name: str, tmp_path: Path) -> None:
    code = f"""
import json, sys
sys.path.insert(0, {str(ROOT)!r})
out = {{"error": None}}
try:
    import {name}
    out["file"] = {name}.__file__
except ImportError as exc:
    out = {{"error": type(exc).__name__, "message": str(exc)}}
out["left_in_sys_modules"] = {name!r} in sys.modules
print(json.dumps(out))
"""
    out = _python(code, tmp_path)
    assert out["error"] == "ImportError", out  # the guard, not "No module named ..."
    assert f"advgame.{name}" in out["message"]
    assert not out["left_in_sys_modules"]


def test_import_advgame_is_light(tmp_path: Path) -> None:
    code = f"""
import json, sys
import advgame
names = dir(advgame)
version = advgame.__version__
after_import = sorted(m for m in {HEAVY!r} if m in sys.modules)
scenarios = advgame.list_scenarios()  # listing imports no simulator either
after_listing = sorted(m for m in {HEAVY!r} if m in sys.modules)
print(json.dumps({{"file": advgame.__file__, "version": version, "after_import": after_import,
                  "after_listing": after_listing, "has_make": "make" in names,
                  "n_scenarios": len(scenarios)}}))
"""
    out = _python(code, tmp_path)
    assert Path(out["file"]).resolve() == ROOT / "advgame" / "__init__.py"
    assert out["version"] == advgame.__version__
    assert out["has_make"]
    assert out["after_import"] == []
    assert out["after_listing"] == []
    assert out["n_scenarios"] > 0
    # the lazy names do resolve on first use (the heavy imports are deferred, not missing)
    code = """
import json, sys
import advgame
game_cls = advgame.Game
print(json.dumps({"gymnasium": "gymnasium" in sys.modules, "name": game_cls.__name__}))
"""
    out = _python(code, tmp_path)
    assert out == {"gymnasium": True, "name": "Game"}


def test_distribution_claims_no_generic_top_level_names(tmp_path: Path) -> None:
    # Read the installed metadata from outside the checkout: in the repository root the build's
    # own advgame.egg-info (source lists) would shadow the installed dist-info.
    code = """
import importlib.metadata, json
dist = importlib.metadata.distribution("advgame")
owners = importlib.metadata.packages_distributions()
print(json.dumps({"top_level": (dist.read_text("top_level.txt") or "").split(),
                  "roots": sorted({f.parts[0] for f in dist.files or ()}),
                  "owners": {k: v for k, v in owners.items() if "advgame" in v}}))
"""
    meta = _python(code, tmp_path)
    assert "advgame" in meta["top_level"]
    assert not set(meta["top_level"]) & set(FOLDERS)
    assert not set(meta["roots"]) & set(FOLDERS), meta["roots"]
    assert "advgame" in meta["owners"]
    for name in FOLDERS:
        assert name not in meta["owners"], name
    # away from the repository, the installed package resolves none of the bare names to ours
    code = f"""
import json, importlib.util
out = {{}}
for name in {FOLDERS!r}:
    spec = importlib.util.find_spec(name)
    out[name] = None if spec is None else spec.origin
out["advgame.agents"] = importlib.util.find_spec("advgame.agents").origin
print(json.dumps(out))
"""
    out = _python(code, tmp_path)
    assert Path(out.pop("advgame.agents")).resolve() == ROOT / "agents" / "__init__.py"
    for name, origin in out.items():
        assert origin is None or not Path(origin).resolve().is_relative_to(ROOT), (name, origin)


def test_advgame_rollout_is_the_function_whatever_was_imported_first() -> None:
    code = (
        "import advgame.core.views, advgame.core.episodes, advgame\n"
        "assert callable(advgame.rollout) and advgame.rollout.__name__ == 'rollout'\n"
        "assert advgame.EpisodeResult.__name__ == 'EpisodeResult'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
