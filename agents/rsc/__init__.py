"""RSC (spurious correlation, causal world model) on SB3's SAC: its config, algorithm and model."""

from advgame.agents.rsc.config import RSCConfig

__all__ = ["RSCConfig"]
