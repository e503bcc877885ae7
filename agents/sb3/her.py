"""Hindsight relabelling under observation attacks: `TrueGoalHerReplayBuffer`.

SB3's `HerReplayBuffer` relabels a transition with an achieved goal read from the stored next
observations and asks the env's ``compute_reward(next achieved goal, new goal)``. Under an
observation attack the stored observations are what the protagonist *saw*: their achieved and
desired goals carry the adversary's δ. Relabelling from them would reward the protagonist
against goals nobody achieved, and no longer be the task's reward.

This buffer keeps what the protagonist saw as its training input, and relabels with the truth:

* it stores, per transition, the true next achieved goal and the true desired goal that an
  advgame robotics task puts in ``info`` (``true_achieved_goal``, ``true_desired_goal``);
* a new goal is the *true* achieved goal of a later transition (SB3's strategies: future,
  final, episode), and the relabelled reward is the task's ``compute_reward`` of the true next
  achieved goal and that goal: a reward the task itself would have given;
* the relabelled desired goal the protagonist is shown is the new goal plus the perturbation
  the adversary put on the desired goal in that transition (stored minus true), so relabelled
  samples are seen through the same attack as the real ones. (The desired goal is constant
  within an episode in Fetch, Hand and Maze, so one true desired goal per transition suffices.)
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.type_aliases import DictReplayBufferSamples

from advgame.errors import ConfigError

__all__ = ["TrueGoalHerReplayBuffer"]

_KEYS = ("true_achieved_goal", "true_desired_goal")


class TrueGoalHerReplayBuffer(HerReplayBuffer):
    """`HerReplayBuffer` relabelling with true goals from ``info`` (see the module docstring).

    Takes SB3's `HerReplayBuffer` arguments (``n_sampled_goal``, ``goal_selection_strategy``);
    pass it as ``replay_buffer_class`` (`advgame.agents.SACConfig(her=True)` does).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        shape = (self.buffer_size, self.n_envs, *self.obs_shape["achieved_goal"])
        self.true_achieved = np.zeros(shape, dtype=np.float64)
        """The true next achieved goal of each stored transition."""
        self.true_desired = np.zeros(shape, dtype=np.float64)
        """The true desired goal of each stored transition."""

    def add(  # type: ignore[override]
        self,
        obs: dict[str, np.ndarray],
        next_obs: dict[str, np.ndarray],
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        """Store a transition and the true goals its infos carry."""
        for i, info in enumerate(infos):
            if not all(k in info for k in _KEYS):
                raise ConfigError(
                    f"TrueGoalHerReplayBuffer needs {list(_KEYS)} in every step's info, got keys "
                    f"{sorted(info)}; train on a view of an advgame robotics scenario with Box "
                    "goals (Fetch, Hand, Maze)."
                )
            self.true_achieved[self.pos, i] = info["true_achieved_goal"]
            self.true_desired[self.pos, i] = info["true_desired_goal"]
        super().add(obs, next_obs, action, reward, done, infos)

    def _sample_goals(self, batch_indices: np.ndarray, env_indices: np.ndarray) -> np.ndarray:
        """SB3's goal selection, reading true achieved goals instead of the stored (seen) ones."""
        seen = self.next_observations
        self.next_observations = {"achieved_goal": self.true_achieved}  # what the parent indexes
        try:
            return super()._sample_goals(batch_indices, env_indices)
        finally:
            self.next_observations = seen

    def _get_virtual_samples(
        self, batch_indices: np.ndarray, env_indices: np.ndarray, env: Any = None
    ) -> DictReplayBufferSamples:
        """Relabelled samples: true new goals, true rewards, seen through the stored attack."""
        at = (batch_indices, env_indices)
        obs = {key: value[at] for key, value in self.observations.items()}
        next_obs = {key: value[at] for key, value in self.next_observations.items()}
        goals = self._sample_goals(batch_indices, env_indices)
        true_desired = self.true_desired[at]
        obs["desired_goal"] = goals + (obs["desired_goal"] - true_desired)
        next_obs["desired_goal"] = goals + (next_obs["desired_goal"] - true_desired)
        infos = (
            copy.deepcopy(self.infos[at]) if self.copy_info_dict else [{} for _ in batch_indices]
        )
        assert self.env is not None, "SB3 sets the buffer's env when the model is built"
        rewards = self.env.env_method(
            "compute_reward", self.true_achieved[at], goals, infos, indices=[0]
        )[0].astype(np.float32)
        dones = self.dones[at] * (1 - self.timeouts[at])
        return DictReplayBufferSamples(
            observations={k: self.to_torch(v) for k, v in self._normalize_obs(obs, env).items()},  # type: ignore[union-attr]
            actions=self.to_torch(self.actions[at]),
            next_observations={
                k: self.to_torch(v)
                for k, v in self._normalize_obs(next_obs, env).items()  # type: ignore[union-attr]
            },
            dones=self.to_torch(dones).reshape(-1, 1),
            rewards=self.to_torch(self._normalize_reward(rewards.reshape(-1, 1), env)),
        )
