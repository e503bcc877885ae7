"""The constrained learners (PPO-Lagrangian, CRPO, PCRPO) on the team PPO core."""

from advgame.agents.safe.safe import (
    SAFE_LEARNERS,
    CRPOConfig,
    PCRPOConfig,
    PIDLagConfig,
    PPOLagConfig,
    SafeLearner,
)

__all__ = [
    "SAFE_LEARNERS",
    "CRPOConfig",
    "PCRPOConfig",
    "PIDLagConfig",
    "PPOLagConfig",
    "SafeLearner",
]
