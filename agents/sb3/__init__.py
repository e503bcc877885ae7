"""Stable-Baselines3's own algorithms as configs: PPO, SAC and TD3 (and HER with true goals).

The base room of the SB3-based families: `sa`, `recurrent`, `ompo`, `rsc` and `dbc` extend these
configs. (SA-PPO's `SAPPOConfig`, here before the rooms, is in `advgame.agents.sa`.)
"""

from advgame.agents.sb3.config import (
    LinearDecay,
    PPOConfig,
    SACConfig,
    TD3Config,
)

__all__ = ["LinearDecay", "PPOConfig", "SACConfig", "TD3Config"]
