"""Stable-Baselines3's own algorithms as configs: PPO, SAC and TD3 (and HER with true goals).

The SB3-based families (`sa`, `recurrent`, `ompo`, `rsc`, `dbc`) extend these configs.
"""

from advgame.agents.sb3.config import (
    LinearDecay,
    PPOConfig,
    SACConfig,
    SAPPOConfig,
    TD3Config,
)

__all__ = ["LinearDecay", "PPOConfig", "SACConfig", "SAPPOConfig", "TD3Config"]
