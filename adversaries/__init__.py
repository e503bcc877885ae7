"""Adversary policies: noise, scheduled shifts, white-box attacks (MAD, critic, PGD, Robust Sarsa, max-cost, PA-AD), LLMs.

Every adversary here is a frozen, picklable *spec* with ``build(info) -> Policy``; the built
policy speaks the one `advgame.core.policy.Policy` interface (``reset(seed)``, ``act(obs)``), so
noise, schedules, networks and language models are interchangeable. Values are given in the
disruptor's raw units (a state offset, newtons, a gravity magnitude) and encoded into the
adversary's bounded action space; the disruptor then clips them into its budget.
"""

if __name__ != "advgame.adversaries":  # pragma: no cover - packaging guard
    raise ImportError(
        "This folder is installed as `advgame.adversaries`; import it under that name "
        "(pip install -e . from the repository root), not as the bare `adversaries`."
    )

from advgame.adversaries.noise import (
    GaussianAdversary,
    RandomAdversary,
    UniformAdversary,
    ZeroAdversary,
)
from advgame.adversaries.paad import PAADAttack
from advgame.adversaries.robust_sarsa import MaxCostAttack, RobustSarsaAttack
from advgame.adversaries.scheduled import ConstantAdversary, SinusoidAdversary
from advgame.adversaries.whitebox import CriticAttack, MADAttack, PGDAttack

# The LLM adversary and its backends load on first use: `import advgame` never imports them.
_LAZY = {
    "LLMAdversary": "advgame.adversaries.llm",
    "LocalModel": "advgame.adversaries.llm_backends",
    "OpenAIEndpoint": "advgame.adversaries.llm_backends",
}


def __getattr__(name: str) -> object:
    """Import the LLM adversary's names when they are first asked for."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'advgame.adversaries' has no attribute {name!r}")


__all__ = [
    "ConstantAdversary",
    "CriticAttack",
    "GaussianAdversary",
    "LLMAdversary",
    "LocalModel",
    "MADAttack",
    "MaxCostAttack",
    "OpenAIEndpoint",
    "PAADAttack",
    "PGDAttack",
    "RandomAdversary",
    "RobustSarsaAttack",
    "SinusoidAdversary",
    "UniformAdversary",
    "ZeroAdversary",
]
