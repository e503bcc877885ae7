"""Single-agent learner configs by algorithm name: SB3's PPO, SAC and TD3, SA-PPO, OMPO, DBC, RSC and RecurrentPPO."""

from __future__ import annotations

from advgame.agents.dbc.config import DBCConfig
from advgame.agents.ompo.config import OMPOConfig
from advgame.agents.recurrent.config import RecurrentPPOConfig
from advgame.agents.rsc.config import RSCConfig
from advgame.agents.sa.config import SAPPOConfig, SARecurrentPPOConfig
from advgame.agents.sb3.config import PPOConfig, SACConfig, TD3Config

__all__ = ["LEARNERS"]

LEARNERS: dict[str, type] = {
    "ppo": PPOConfig,
    "sa-ppo": SAPPOConfig,
    "sac": SACConfig,
    "td3": TD3Config,
    "ompo": OMPOConfig,
    "dbc": DBCConfig,
    "rsc": RSCConfig,
    "recurrent-ppo": RecurrentPPOConfig,
    "sa-recurrent-ppo": SARecurrentPPOConfig,
}
"""Learner configs by algorithm name (`advgame.training.TrainConfig.protagonist_algo`)."""
