"""Protagonist learners: Stable-Baselines3 PPO/SAC/TD3 configs, SA-PPO, OMPO, DBC, RSC, LSTM PPO (plain and SA), and MAPPO/IPPO for teams."""

if __name__ != "advgame.agents":  # pragma: no cover - packaging guard
    raise ImportError(
        "This folder is installed as `advgame.agents`; import it under that name "
        "(pip install -e . from the repository root), not as the bare `agents`."
    )

from advgame.agents.dbc.config import DBCConfig
from advgame.agents.learners import LEARNERS
from advgame.agents.marl.marl import MARL_LEARNERS, IPPOConfig, MAPPOConfig, TeamLearner
from advgame.agents.ompo.config import OMPOConfig
from advgame.agents.recurrent.config import RecurrentPPOConfig
from advgame.agents.rsc.config import RSCConfig
from advgame.agents.sa.config import SARecurrentPPOConfig
from advgame.agents.sb3.config import PPOConfig, SACConfig, SAPPOConfig, TD3Config

__all__ = [
    "LEARNERS",
    "MARL_LEARNERS",
    "DBCConfig",
    "IPPOConfig",
    "MAPPOConfig",
    "OMPOConfig",
    "PPOConfig",
    "RSCConfig",
    "RecurrentPPOConfig",
    "SACConfig",
    "SAPPOConfig",
    "SARecurrentPPOConfig",
    "TD3Config",
    "TeamLearner",
]
