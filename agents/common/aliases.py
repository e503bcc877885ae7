"""Old module names of `advgame.agents` import as the modules that replaced them.

Files outside advgame's own readers name classes by module: Stable-Baselines3's zips cloudpickle
the policy class, the learning-rate schedule and the replay buffer class (for example
``advgame.agents.dbc_nets.DBCPolicy``, written before agents/ had one folder per family), and
unpickling imports that module. The table is `advgame.core.moved.MOVED` (old name -> new name,
the one table advgame's pickle readers and part-file digests use too); this module adds an import
hook that serves each old ``advgame.agents.*`` name as the *same module object* as its new one,
so ``advgame.agents.dbc_nets.DBCPolicy is advgame.agents.dbc.nets.DBCPolicy``.

An old name that is now its family's folder (``advgame.agents.rsc``: the module that held `RSC`
is the package `advgame.agents.rsc`) is not aliased: the package exposes the old module's
public names (`lazy_exports` keeps the heavy ones unimported until used).

The hook is installed when `advgame.agents` is imported, which every import of an
``advgame.agents.*`` name does first.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from collections.abc import Callable, Mapping
from types import ModuleType
from typing import Any

from advgame.core.moved import MOVED, current

__all__ = ["OldNames", "install", "lazy_exports", "old_names"]

_PREFIX = "advgame.agents."


def old_names() -> dict[str, str]:
    """Every old ``advgame.agents.*`` module name -> the module that replaced it."""
    return {old: current(old)[0] for old in MOVED if old.startswith(_PREFIX)}


class OldNames(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old module name of `advgame.agents` and loads it as its new module.

    It sits last on `sys.meta_path`, so a real module or package of that name always wins.
    """

    def find_spec(
        self, fullname: str, path: Any = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        """A spec for `fullname` when it is an old name, None otherwise."""
        if not fullname.startswith(_PREFIX) or fullname not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> None:
        """The default module: `exec_module` replaces it."""
        return None

    def exec_module(self, module: ModuleType) -> None:
        """Put the new module in `sys.modules` under the old name (the import returns it)."""
        sys.modules[module.__name__] = importlib.import_module(current(module.__name__)[0])


def install() -> None:
    """Put one `OldNames` at the end of `sys.meta_path` (again: nothing changes)."""
    if not any(isinstance(finder, OldNames) for finder in sys.meta_path):
        sys.meta_path.append(OldNames())


def lazy_exports(
    package: str, names: Mapping[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A package's PEP 562 ``__getattr__`` and ``__dir__`` for `names` (attribute -> submodule).

    Example:
        ``__getattr__, __dir__ = lazy_exports(__name__, {"RSC": "rsc"})`` in
        ``agents/rsc/__init__.py``: ``advgame.agents.rsc.RSC`` imports ``advgame.agents.rsc.rsc``
        on first use.

    """

    def getattr_(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{names[name]}"), name)

    def dir_() -> list[str]:
        return sorted({*vars(sys.modules[package]), *names})

    return getattr_, dir_


install()
