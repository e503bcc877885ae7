"""The constrained learners (PPO-Lagrangian, PID-Lagrangian, CRPO, PCRPO) on the team PPO core."""

from advgame.agents.common.aliases import lazy_exports

__all__ = ["SAFE_LEARNERS", "CRPOConfig", "PCRPOConfig",
           "PIDLagConfig", "PPOLagConfig", "SafeLearner"]  # fmt: skip

# imported on first use; old pickles name them here (the module advgame.agents.safe)
__getattr__, __dir__ = lazy_exports(__name__, dict.fromkeys(__all__, "safe"))
