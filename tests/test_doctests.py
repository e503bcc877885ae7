"""The examples in docstrings run (each public wrapper has a short doctest, as in Gymnasium)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import advgame

PACKAGES = ("advgame", "advgame.adversaries", "advgame.scenarios", "advgame.agents")


def _modules() -> list[str]:
    names: set[str] = set()
    for package in PACKAGES:
        module = importlib.import_module(package)
        names.add(package)
        for info in pkgutil.walk_packages(module.__path__, prefix=f"{package}."):
            names.add(info.name)
    return sorted(names)


MODULES = _modules()


def test_the_walk_finds_the_core_modules() -> None:
    assert {
        "advgame.core.game",
        "advgame.disruptors.observation",
        "advgame.adversaries.noise",
    } <= set(MODULES)
    assert advgame.__version__


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name: str) -> None:
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0, (
        f"{result.failed} of {result.attempted} doctest examples failed in {name}"
    )
