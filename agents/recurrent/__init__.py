"""LSTM PPO: sb3-contrib"s RecurrentPPO with each minibatch unrolled in one LSTM call."""

from advgame.agents.common.aliases import lazy_exports
from advgame.agents.recurrent.config import RecurrentPPOConfig

# the learner (torch, SB3) is imported on first use; old pickles name it here too
__getattr__, __dir__ = lazy_exports(__name__, {"UnrolledRecurrentPPO": "ppo"})

__all__ = ["RecurrentPPOConfig", "UnrolledRecurrentPPO"]
