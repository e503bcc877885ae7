"""Adversary policies: noise, scheduled shifts, white-box attacks (MAD, critic, PGD), and more.

Every adversary here is a frozen, picklable *spec* with ``build(info) -> Policy``; the built
policy speaks the one `advgame.policy.Policy` interface (``reset(seed)``, ``act(obs)``), so
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
from advgame.adversaries.scheduled import ConstantAdversary, SinusoidAdversary
from advgame.adversaries.whitebox import CriticAttack, MADAttack, PGDAttack

__all__ = [
    "ConstantAdversary",
    "CriticAttack",
    "GaussianAdversary",
    "MADAttack",
    "PGDAttack",
    "RandomAdversary",
    "SinusoidAdversary",
    "UniformAdversary",
    "ZeroAdversary",
]
