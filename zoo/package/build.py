"""Build ``advgame-zoo``: the zoo's released agents as a data-only distribution (sdist and wheel).

The package holds ``manifest.json`` and every file an entry of it names (protagonist, its
normalizer, its released adversary), laid out as in the repository's ``zoo/`` folder, under the
import name ``advgame_zoo``; `advgame.workflows.zoo.default_root` finds it when it is installed.
Its version is advgame's (read from pyproject.toml), and advgame's ``zoo`` extra pins it, so an
installed advgame and its zoo always come from one release. Campaign runs, part files and
tables stay in the repository: only what the manifest releases is packaged.

    python zoo/package/build.py                 # dist/advgame_zoo-<version>*.whl and .tar.gz
    python zoo/package/build.py --out wheels    # elsewhere
    pip install dist/advgame_zoo-*.whl          # or: pip install "advgame[zoo]" once published
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ZOO = ROOT / "zoo"
NAME = "advgame-zoo"
MODULE = "advgame_zoo"


def version() -> str:
    """The version of advgame, from the repository's pyproject.toml (the zoo's is the same)."""
    return str(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"])


def released_files(zoo: Path = ZOO) -> list[str]:
    """The manifest and every file its entries release, relative to `zoo`, checked by sha256."""
    manifest = json.loads((zoo / "manifest.json").read_text())
    files = ["manifest.json"]
    for entry in manifest["entries"]:
        for role, f in entry["files"].items():
            data = (zoo / f["path"]).read_bytes()
            if hashlib.sha256(data).hexdigest() != f["sha256"]:
                raise SystemExit(f"{entry['id']}: {role} file {f['path']} differs from its sha256")
            files.append(f["path"])
    return files


def stage(dest: Path, zoo: Path = ZOO) -> Path:
    """Lay out the package's project in `dest` (pyproject, README, ``advgame_zoo/``)."""
    package = dest / MODULE
    for rel in released_files(zoo):
        (package / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(zoo / rel, package / rel)
    (package / "__init__.py").write_text(
        f'"""The released agents of advgame\'s zoo (data only; read by advgame.workflows.zoo)."""\n'
        f'\n__version__ = "{version()}"\n'
    )
    (dest / "README.md").write_text((Path(__file__).parent / "README.md").read_text())
    (dest / "pyproject.toml").write_text(
        f"""[build-system]
requires = ["setuptools>=69"]
build-backend = "setuptools.build_meta"

[project]
name = "{NAME}"
version = "{version()}"
description = "The released agents of advgame's zoo (trained policies, normalizers, adversaries)."
readme = "README.md"
requires-python = ">=3.11"

[tool.setuptools]
packages = ["{MODULE}"]
include-package-data = true

[tool.setuptools.package-data]
"{MODULE}" = ["manifest.json", "*/*/*"]
"""
    )
    return dest


def build(out: Path, zoo: Path = ZOO) -> list[Path]:
    """Build the sdist and the wheel of the zoo package into `out`; return their paths."""
    out.mkdir(parents=True, exist_ok=True)
    made = []
    with tempfile.TemporaryDirectory() as tmp:
        project = stage(Path(tmp) / "advgame-zoo", zoo)
        for hook in ("build_sdist", "build_wheel"):  # one process each, as pip's frontends do
            code = (
                f"import sys; from setuptools import build_meta as b; print(b.{hook}(sys.argv[1]))"
            )
            done = subprocess.run(
                [sys.executable, "-c", code, str(out.resolve())],
                cwd=project,
                check=True,
                capture_output=True,
                text=True,
            )
            made.append(out / done.stdout.strip().splitlines()[-1])
    return made


def main() -> None:
    """Build into ``--out`` (default ``dist/``) and print the files and their sizes."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=str(ROOT / "dist"), help="output folder (default dist/)")
    args = parser.parse_args()
    for path in build(Path(args.out)):
        print(f"{path} ({path.stat().st_size / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
