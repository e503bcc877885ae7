"""SA-PPO (state-adversarial regulariser) and its recurrent form on the unrolled LSTM PPO."""

from advgame.agents.sa.config import SARecurrentPPOConfig

__all__ = ["SARecurrentPPOConfig"]
