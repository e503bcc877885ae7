"""`ActionMaskObservations`: each agent's observation in PettingZoo's action-mask form.

PettingZoo's games with illegal moves give each agent ``{"observation": obs, "action_mask":
mask}``, and some clients branch on that form rather than on the action space. Tianshou 2.0.1's
``PettingZooEnv`` passes a ``mask`` to its policies only for such observations (or a ``Discrete``
action space), and its ``MultiAgentPolicy`` takes a different path without one, a path that
fails while actions are computed (docs/interop.md). In an advgame game every action is legal, so
the mask is all ones: it changes the observation's form, never what an agent may do.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo.utils.wrappers import BaseParallelWrapper

__all__ = ["ActionMaskObservations"]


class ActionMaskObservations(BaseParallelWrapper):
    """A parallel game whose observations are ``{"observation": obs, "action_mask": ones}``.

    Each agent's mask has one int8 entry per component of its flattened action space
    (``gymnasium.spaces.flatdim``: ``n`` for ``Discrete(n)``, the size of a ``Box``), all 1.
    Wrap last, after any wrapper that changes the spaces (SuperSuit's padding), so the mask
    matches the action space the client sees. An adapter for clients only: PettingZoo's
    ``parallel_api_test`` samples each action with its agent's mask, which Gymnasium's ``Box``
    refuses (``Box.sample cannot be provided a mask``), so run PettingZoo's checks on the game.

    Args:
        env: the game, or a wrapper of it (any PettingZoo ``ParallelEnv``).

    Example:
        >>> import advgame
        >>> from advgame.interop import ActionMaskObservations
        >>> game = ActionMaskObservations(advgame.make("Hopper-v5", preset="default"))
        >>> observations, _ = game.reset(seed=0)
        >>> sorted(observations["protagonist"])
        ['action_mask', 'observation']
        >>> observations["protagonist"]["action_mask"]
        array([1, 1, 1], dtype=int8)

    """

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self._masks = {a: spaces.flatdim(env.action_space(a)) for a in env.possible_agents}
        self.observation_spaces = {
            a: spaces.Dict(
                {
                    "observation": env.observation_space(a),
                    "action_mask": spaces.Box(0, 1, (n,), np.int8),
                }
            )
            for a, n in self._masks.items()
        }

    def observation_space(self, agent: str) -> spaces.Dict:
        """The agent's observation space: its game's space beside a ``Box(0, 1, (n,), int8)``."""
        return self.observation_spaces[agent]

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Reset the game; each observation carries an all-ones action mask."""
        observations, infos = self.env.reset(seed=seed, options=options)
        return self._masked(observations), infos

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Make one move; each observation carries an all-ones action mask."""
        observations, rewards, terminations, truncations, infos = self.env.step(actions)
        return self._masked(observations), rewards, terminations, truncations, infos

    def _masked(self, observations: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
        return {
            agent: {"observation": obs, "action_mask": np.ones(self._masks[agent], np.int8)}
            for agent, obs in observations.items()
        }
