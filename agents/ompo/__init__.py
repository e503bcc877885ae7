"""OMPO (shifting dynamics) on SB3's SAC: its config, algorithm, replay buffer and networks."""

from advgame.agents.ompo.config import OMPOConfig

__all__ = ["OMPOConfig"]
