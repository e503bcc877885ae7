"""DBC (bisimulation representations) on SB3's SAC: its config, algorithm and networks."""

from advgame.agents.common.aliases import lazy_exports
from advgame.agents.dbc.config import DBCConfig

# the learner (torch, SB3) is imported on first use; old pickles name it here too
__getattr__, __dir__ = lazy_exports(
    __name__,
    {"DBC": "dbc", "bisimulation_loss": "dbc", "reward_loss": "dbc", "transition_loss": "dbc"},
)

__all__ = ["DBC", "DBCConfig", "bisimulation_loss", "reward_loss", "transition_loss"]
