"""Disruptors: what an adversary may perturb, each one hook plus a budget.

`kinds.KINDS` maps a kind name (as used in dict configs and on the command line) to its spec
class; a new disruptor is one file plus one line there. The contract every disruptor keeps
(`Disruptor`, `DisruptorSpec`) is `advgame.core.disruptor`, beside the game that calls it.
"""

from __future__ import annotations

from advgame.core.disruptor import Disruptor, DisruptorSpec
from advgame.disruptors.action import ActionDisruptor
from advgame.disruptors.arm import ArmDisruptor
from advgame.disruptors.dynamics import DynamicsDisruptor, Param
from advgame.disruptors.force import ForceDisruptor
from advgame.disruptors.kinds import KINDS, from_config
from advgame.disruptors.observation import ObservationDisruptor
from advgame.disruptors.reward import RewardDisruptor
from advgame.disruptors.workspace import Shift, WorkspaceDisruptor

__all__ = [
    "KINDS",
    "ActionDisruptor",
    "ArmDisruptor",
    "Disruptor",
    "DisruptorSpec",
    "DynamicsDisruptor",
    "ForceDisruptor",
    "ObservationDisruptor",
    "Param",
    "RewardDisruptor",
    "Shift",
    "WorkspaceDisruptor",
    "from_config",
]
