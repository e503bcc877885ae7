"""Shared by the Game contract tests (tests/test_game_*.py): agent names, a Hopper-v5 game
builder, filler actions for every agent, and a seeded random protagonist."""

from __future__ import annotations

from typing import Any

import numpy as np

import advgame
from advgame.core.episodes import filler_action

P = "protagonist"
OBS, ACT, REW, DYN, FORCE = (
    "observation_adversary",
    "action_adversary",
    "reward_adversary",
    "dynamics_adversary",
    "force_adversary",
)


# -- helpers ---------------------------------------------------------------------------------
def hopper(disruptors: Any, steps: int = 30, **kwargs: Any) -> advgame.Game:
    return advgame.make("Hopper-v5", disruptors=disruptors, max_episode_steps=steps, **kwargs)


def fillers(game: advgame.Game, **given: Any) -> dict[str, Any]:
    """A valid action for every agent, with `given` overriding some of them."""
    out = {a: filler_action(game.action_space(a)) for a in game.possible_agents}
    out.update(given)
    return out


class ProtagonistRng:
    """Uniformly random protagonist actions from a generator of its own."""

    def __init__(self, game: advgame.Game, seed: int) -> None:
        self.space = game.action_space(P)
        self.rng = np.random.default_rng(seed)

    def __call__(self) -> np.ndarray:
        return self.rng.uniform(self.space.low, self.space.high).astype(self.space.dtype)
