"""Gymnasium Box2D scenarios: observation, reward and action disruptors.

Presets: ``default`` (bounded observation and action adversaries), ``full`` (plus reward), and
the paper's random-mode settings. LunarLander-v3 has discrete actions: its action adversary
is the probabilistic form (with probability α its choice replaces the lander's). CarRacing's
observation budget is in pixel intensity units (0-255).
"""

from __future__ import annotations

from advgame.core.registry import Preset
from advgame.disruptors import ActionDisruptor, ObservationDisruptor, RewardDisruptor
from advgame.scenarios.common import gaussian_presets, make_task

__all__ = ["make_task", "presets"]

_OBS_EPS = {"CarRacing-v3": 8.0}


def presets(env_id: str) -> dict[str, Preset]:
    """The presets of Box2D scenario `env_id`."""
    obs = ObservationDisruptor(eps=_OBS_EPS.get(env_id, 0.1))
    discrete = env_id == "LunarLander-v3"
    act = ActionDisruptor(mode="probabilistic", alpha=0.1) if discrete else ActionDisruptor(eps=0.1)
    what = "probabilistic (α = 0.1)" if discrete else "ε = 0.1"
    return {
        "default": Preset(
            (obs, act), description=f"bounded observation and action ({what}) adversaries"
        ),
        "full": Preset(
            (obs, RewardDisruptor(eps=0.1), act),
            description="observation, reward and action adversaries",
        ),
        **gaussian_presets(action=act if discrete else None),
    }
