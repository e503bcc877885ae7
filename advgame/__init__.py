"""advgame: robust reinforcement learning as adversarial PettingZoo games.

Every Disrupted-MDP (Robust Gymnasium, sections 2-3) becomes a `pettingzoo.ParallelEnv` whose
agents are the task's protagonists and one bounded adversary per disruptor::

    import advgame
    advgame.list_scenarios()
    game = advgame.make("HalfCheetah-v5", preset="atla")
    game.protagonists, game.adversaries

Importing the package is cheap: simulators, torch and the registry load on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

# public name -> module that defines it (imported on first attribute access)
_LAZY = {
    "make": "advgame.core.registry",
    "list_scenarios": "advgame.core.registry",
    "scenario_spec": "advgame.core.registry",
    "register": "advgame.core.registry",
    "Preset": "advgame.core.registry",
    "ScenarioSpec": "advgame.core.registry",
    "Game": "advgame.core.game",
    "Schedule": "advgame.core.schedule",
    "ObservationDisruptor": "advgame.disruptors",
    "ActionDisruptor": "advgame.disruptors",
    "RewardDisruptor": "advgame.disruptors",
    "DynamicsDisruptor": "advgame.disruptors",
    "ForceDisruptor": "advgame.disruptors",
    "Param": "advgame.disruptors",
    "WorkspaceDisruptor": "advgame.disruptors",
    "Shift": "advgame.disruptors",
    "ArmDisruptor": "advgame.disruptors",
    "AgentInfo": "advgame.core.policy",
    "Policy": "advgame.core.policy",
    "PolicySpec": "advgame.core.policy",
    "SingleAgentView": "advgame.core.views",
    "view_factory": "advgame.core.views",
    "VectorView": "advgame.core.vector",
    "rollout": "advgame.core.episodes",
    "EpisodeResult": "advgame.core.episodes",
    "AdvgameError": "advgame.errors",
}

__all__ = sorted(_LAZY)

if TYPE_CHECKING:
    from advgame.core.episodes import EpisodeResult, rollout
    from advgame.core.game import Game
    from advgame.core.policy import AgentInfo, Policy, PolicySpec
    from advgame.core.registry import (
        Preset,
        ScenarioSpec,
        list_scenarios,
        make,
        register,
        scenario_spec,
    )
    from advgame.core.schedule import Schedule
    from advgame.core.vector import VectorView
    from advgame.core.views import SingleAgentView, view_factory
    from advgame.disruptors import (
        ActionDisruptor,
        ArmDisruptor,
        DynamicsDisruptor,
        ForceDisruptor,
        ObservationDisruptor,
        Param,
        RewardDisruptor,
        Shift,
        WorkspaceDisruptor,
    )
    from advgame.errors import AdvgameError


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'advgame' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_LAZY])
