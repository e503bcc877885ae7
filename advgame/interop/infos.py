"""`FixedInfos`: the same numeric ``infos`` keys for every agent on every reset and move.

A game's ``infos`` differ between moves: a sense move tells the protagonist only whether its
action counted (``{"acted": False}``), an act move adds the task's own keys and the true payoff,
and a reset has neither. Clients that turn infos into fixed-shape tensors from the first reset
(TorchRL's ``PettingZooWrapper``) fail on the first key they have not seen. `FixedInfos` gives
every agent the same float keys always (0 where a move did not report one), so ``acted`` reaches
such a client as a tensor it can mask its losses with.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from pettingzoo.utils.wrappers import BaseParallelWrapper

__all__ = ["FixedInfos"]

KEYS = ("acted", "true_reward", "true_cost", "payoff")
"""The keys kept by default: whose action counted, and the true payoff the game reports."""


class FixedInfos(BaseParallelWrapper):
    """A game whose per-agent ``infos`` always hold `keys`, as float32 scalars.

    Args:
        env: the game (or a wrapper of it).
        keys: the info keys every agent gets; a key a move does not report is 0.

    Example:
        >>> import advgame
        >>> from advgame.interop import FixedInfos
        >>> game = FixedInfos(advgame.make("Hopper-v5", preset="default"))
        >>> _, infos = game.reset(seed=0)
        >>> sorted(infos["protagonist"])
        ['acted', 'payoff', 'true_cost', 'true_reward']

    """

    def __init__(self, env: Any, keys: Sequence[str] = KEYS) -> None:
        super().__init__(env)
        self.keys = tuple(keys)

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Reset the game; every agent's infos hold `keys` (0 before the first move)."""
        observations, infos = self.env.reset(seed=seed, options=options)
        return observations, self._fixed(infos)

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Make one move; every agent's infos hold `keys`."""
        observations, rewards, terminations, truncations, infos = self.env.step(actions)
        return observations, rewards, terminations, truncations, self._fixed(infos)

    def _fixed(self, infos: Mapping[str, Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
        return {
            agent: {k: np.float32(info.get(k, 0.0)) for k in self.keys}
            for agent, info in infos.items()
        }
