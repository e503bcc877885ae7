"""OMPO (shifting dynamics) on SB3's SAC: its config, algorithm, replay buffer and networks."""

from advgame.agents.common.aliases import lazy_exports
from advgame.agents.ompo.config import OMPOConfig

# the learner (torch, SB3) is imported on first use; old pickles name it here too
__getattr__, __dir__ = lazy_exports(
    __name__, {"OMPO": "ompo", "OMPOReplayBuffer": "ompo", "TransitionDiscriminator": "ompo"}
)

__all__ = ["OMPO", "OMPOConfig", "OMPOReplayBuffer", "TransitionDiscriminator"]
