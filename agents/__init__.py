"""Protagonist learners, one folder per family, and the common room they share.

`sb3` (Stable-Baselines3's PPO, SAC, TD3), `sa` (SA-PPO, plain and LSTM), `recurrent` (LSTM PPO),
`ompo`, `rsc`, `dbc` (the paper's robust baselines on SB3's SAC), `marl` (MAPPO/IPPO for teams)
and `safe` (the constrained learners); `common` holds what they share, and `learners` names every
single-agent config by its algorithm. Importing this package also makes the modules' names from
before the folders (``advgame.agents.rsc_model``, ...) import as their new modules
(`advgame.agents.common.aliases`), so saved models that name them load.
"""

if __name__ != "advgame.agents":  # pragma: no cover - packaging guard
    raise ImportError(
        "This folder is installed as `advgame.agents`; import it under that name "
        "(pip install -e . from the repository root), not as the bare `agents`."
    )

from advgame.agents.common import aliases as _aliases  # noqa: F401  (old module names import)
from advgame.agents.dbc.config import DBCConfig
from advgame.agents.learners import LEARNERS
from advgame.agents.marl.marl import MARL_LEARNERS, IPPOConfig, MAPPOConfig, TeamLearner
from advgame.agents.ompo.config import OMPOConfig
from advgame.agents.recurrent.config import RecurrentPPOConfig
from advgame.agents.rsc.config import RSCConfig
from advgame.agents.sa.config import SAPPOConfig, SARecurrentPPOConfig
from advgame.agents.sb3.config import PPOConfig, SACConfig, TD3Config

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
