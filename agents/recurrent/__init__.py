"""LSTM PPO: sb3-contrib's RecurrentPPO with each minibatch unrolled in one LSTM call."""

from advgame.agents.recurrent.config import RecurrentPPOConfig

__all__ = ["RecurrentPPOConfig"]
