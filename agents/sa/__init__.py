"""SA-PPO (the state-adversarial regulariser) and its recurrent form on the unrolled LSTM PPO."""

from advgame.agents.common.aliases import lazy_exports
from advgame.agents.sa.config import SAPPOConfig, SARecurrentPPOConfig

# the learners (torch, SB3) are imported on first use
__getattr__, __dir__ = lazy_exports(__name__, {"SAPPO": "ppo", "SARecurrentPPO": "recurrent"})

__all__ = ["SAPPO", "SAPPOConfig", "SARecurrentPPO", "SARecurrentPPOConfig"]
