"""Adapters that let the ecosystem's multi-agent clients read an advgame game (docs/interop.md).

Most clients take a `Game` as it is (it is a PettingZoo ``ParallelEnv``); these adapters cover
what some of them cannot read on their own.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_LAZY = {
    "ActionMaskObservations": "advgame.interop.masks",
    "FixedInfos": "advgame.interop.infos",
}

__all__ = ["ActionMaskObservations", "FixedInfos"]

if TYPE_CHECKING:
    from advgame.interop.infos import FixedInfos
    from advgame.interop.masks import ActionMaskObservations


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_LAZY])
