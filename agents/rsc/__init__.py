"""RSC (spurious correlation, causal world model) on SB3's SAC: its config, algorithm and model."""

from advgame.agents.common.aliases import lazy_exports
from advgame.agents.rsc.config import RSCConfig

# the learner (torch, SB3) is imported on first use; old pickles name it here too
__getattr__, __dir__ = lazy_exports(
    __name__,
    {"MODE_ERROR_EVERY": "rsc", "RSC": "rsc", "graph_logs": "rsc", "one_step_samples": "rsc"},
)

__all__ = ["MODE_ERROR_EVERY", "RSC", "RSCConfig", "graph_logs", "one_step_samples"]
