"""The zoo as a package of its own: built from zoo/, found when installed, loud when absent."""

from __future__ import annotations

import importlib.metadata
import json
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from packaging.requirements import Requirement

import advgame
from advgame.errors import ConfigError, FileFormatError
from advgame.workflows import zoo

ROOT = Path(advgame.__file__).resolve().parents[1]
MANIFEST = ROOT / "zoo" / "manifest.json"

pytestmark = pytest.mark.skipif(not MANIFEST.is_file(), reason="no zoo in this checkout")


@pytest.fixture(scope="module")
def package() -> object:
    """zoo/package/build.py as a module."""
    sys.path.insert(0, str(ROOT / "zoo" / "package"))
    try:
        import build
    finally:
        sys.path.pop(0)
    return build


def test_the_zoo_extra_pins_the_package_at_advgames_own_version(package: object) -> None:
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert package.version() == version == advgame.__version__  # type: ignore[attr-defined]
    reqs = [Requirement(r) for r in importlib.metadata.requires("advgame") or []]
    (zoo_req,) = [r for r in reqs if r.name == "advgame-zoo"]
    assert str(zoo_req.specifier) == f"=={version}"
    assert zoo_req.marker is not None and zoo_req.marker.evaluate({"extra": "zoo"})


def test_the_wheel_holds_every_released_file_and_is_found_when_installed(
    package: object, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    made = package.build(tmp_path / "dist")  # type: ignore[attr-defined]
    (wheel,) = [p for p in made if p.suffix == ".whl"]
    assert any(p.name.endswith(".tar.gz") for p in made)
    entries = json.loads(MANIFEST.read_text())["entries"]
    released = {f["path"] for e in entries for f in e["files"].values()}
    with zipfile.ZipFile(wheel) as whl:
        names = set(whl.namelist())
        assert {f"advgame_zoo/{p}" for p in released | {"manifest.json"}} <= names
        assert not any("/finished/" in n or "/results/" in n for n in names)  # releases only
        whl.extractall(tmp_path / "site")  # installing a pure wheel is unpacking it
    monkeypatch.delenv("ADVGAME_ZOO", raising=False)
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    monkeypatch.chdir(tmp_path)
    assert zoo.default_root() == tmp_path / "site" / "advgame_zoo"  # before the checkout's
    assert len(zoo.entries()) == len(entries) >= 21  # every entry of the checkout's manifest
    spec = zoo.load("hopper/ppo")  # checksums verified against the packaged manifest
    assert Path(spec.path).is_relative_to(tmp_path / "site")
    # a damaged packaged file is refused as a checkout's would be
    (tmp_path / "site" / "advgame_zoo" / "hopper" / "ppo" / "normalizer.npz").write_bytes(b"x")
    with pytest.raises(FileFormatError, match="sha256"):
        zoo.load("hopper/ppo")


def test_without_a_zoo_every_path_says_what_is_missing_and_how_to_install_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from advgame.cli import main

    monkeypatch.setenv("ADVGAME_ZOO", str(tmp_path / "none"))
    assert main(["zoo", "list"]) == 0
    assert zoo.INSTALL in capsys.readouterr().out
    assert main(["evaluate", "--zoo", "hopper/ppo", "--out", str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err
    assert "hopper/ppo" in err and zoo.INSTALL in err
    with pytest.raises(ConfigError, match="advgame-zoo"):
        zoo.load("hopper/ppo")
