"""MAPPO and IPPO for teams of protagonists (MaMuJoCo): compact torch learners over a team view."""

from advgame.agents.marl.marl import (
    MARL_LEARNERS,
    IPPOConfig,
    MAPPOConfig,
    TeamLearner,
    TeamPPOConfig,
)

__all__ = ["MARL_LEARNERS", "IPPOConfig", "MAPPOConfig", "TeamLearner", "TeamPPOConfig"]
