"""Scenarios: the task bases (MuJoCo, Box2D, robotics, MaMuJoCo, robosuite) and their presets.

`builtin` registers every built-in scenario under its id (importing this package does it);
each family's task base and disruptor presets live in a module of their own.
"""

if __name__ != "advgame.scenarios":  # pragma: no cover - packaging guard
    raise ImportError(
        "This folder is installed as `advgame.scenarios`; import it under that name "
        "(pip install -e . from the repository root), not as the bare `scenarios`."
    )

from advgame.scenarios.builtin import EXTRAS

__all__ = ["EXTRAS"]
