"""The gymnasium-robotics task base: Maze, Fetch, Shadow Hand, Adroit and Franka Kitchen.

`RoboticsTask` is a `GymTask` that knows three things the plain one does not:

* **Dict observations** (Maze, Fetch, Hand, Kitchen) stay Dicts for the protagonist; the true
  state adversaries observe is every leaf concatenated in the Dict space's order, depth first
  (``achieved_goal``, ``desired_goal``, ``observation``; Kitchen's nested goals by task name),
  a float64 `Box` (`advgame.disruptors.dict_obs.flat_space`).
* **Where the MuJoCo model lives**: Maze wraps an inner ``point_env``/``ant_env``, Kitchen a
  ``robot_env``; environment disruptors edit that model (and `Game` restores it on reset).
* **Success and true goals**: every step's info has ``is_success`` (Fetch and Hand report it;
  Maze and Adroit say ``success``; Kitchen succeeds when no task is left), and for Box goals
  ``true_achieved_goal``/``true_desired_goal``, the goals the task rewards against, which HER
  relabels with (`advgame.agents.sb3.her`). `compute_reward` is the task's own.

Rewards come from the simulator's true state: an observation disruptor changes only the copy the
protagonist is shown, never what the task computes its reward and success from.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces

from advgame.core.task import GymTask, MujocoSim, StepResult
from advgame.disruptors import dict_obs
from advgame.errors import ConfigError

__all__ = ["RoboticsTask"]

_INNER = ("point_env", "ant_env", "robot_env")
"""Attributes of gymnasium-robotics envs that hold the MuJoCo env actually simulated."""


def _copy(obs: Any) -> Any:
    """A fresh copy of an observation (Kitchen returns the same arrays step after step)."""
    if isinstance(obs, Mapping):
        return {k: _copy(v) for k, v in obs.items()}
    return np.array(obs, copy=True)


class RoboticsTask(GymTask):
    """A gymnasium-robotics env as a single-protagonist task base (see the module docstring).

    Args:
        env_id: a registered gymnasium-robotics id, e.g. ``"FetchPush-v4"``.
        **kwargs: passed to `gymnasium.make` (``max_episode_steps``, ``reward_type``, ...).

    """

    def __init__(self, env_id: str, **kwargs: Any) -> None:
        import gymnasium as gym
        import gymnasium_robotics

        gym.register_envs(gymnasium_robotics)
        super().__init__(env_id, **kwargs)
        space = self.env.observation_space
        self.dict_obs = isinstance(space, spaces.Dict)
        """Whether the protagonist observes a Dict (goal-conditioned tasks)."""
        self.leaf_names: list[str] = []
        """The Dict's leaves in state order (empty for Box observations)."""
        if isinstance(space, spaces.Dict):
            self.leaf_names = [name for name, _ in dict_obs.leaves(space)]
            self.state_space = dict_obs.flat_space(space)
        goals = (
            [space[k] for k in ("achieved_goal", "desired_goal") if k in space.spaces]
            if isinstance(space, spaces.Dict)
            else []
        )
        self.box_goals = len(goals) == 2 and all(isinstance(g, spaces.Box) for g in goals)
        """Whether the goals are Boxes (HER can relabel them; Kitchen's nested goals cannot)."""
        if self.box_goals:
            self.goal_reward = self.compute_reward

    def reset(self, seed: int | None) -> tuple[dict[str, Any], dict[str, Any]]:
        """Reset the env with `seed`; the info says ``is_success`` from the start."""
        observations, info = super().reset(seed)
        obs = _copy(observations[self.AGENT])
        return {self.AGENT: obs}, self._annotate(obs, dict(info))

    def step(self, actions: Mapping[str, Any]) -> StepResult:
        """Step the env; reward and ``is_success`` are the task's, from its true state."""
        observations, reward, cost, terminated, truncated, info = super().step(actions)
        obs = _copy(observations[self.AGENT])
        return (
            {self.AGENT: obs},
            reward,
            cost,
            terminated,
            truncated,
            self._annotate(obs, dict(info)),
        )

    def _annotate(self, obs: Any, info: dict[str, Any]) -> dict[str, Any]:
        """Add ``is_success`` and the true goals (copies of the true observation's) to `info`."""
        if "is_success" not in info:
            if "success" in info:
                info["is_success"] = float(bool(info["success"]))
            elif "tasks_to_complete" in info:  # Kitchen: every task of the episode done
                info["is_success"] = float(len(info["tasks_to_complete"]) == 0)
            elif self.box_goals:  # Fetch and Hand at reset: their own success test
                check = self.env.unwrapped._is_success  # type: ignore[attr-defined]
                info["is_success"] = float(check(obs["achieved_goal"], obs["desired_goal"]))
        if self.box_goals:
            info["true_achieved_goal"] = obs["achieved_goal"].copy()
            info["true_desired_goal"] = obs["desired_goal"].copy()
        return info

    def state(self, observations: Mapping[str, Any]) -> Any:
        """The true state: a Dict observation's leaves concatenated (Box observations as is)."""
        obs = observations[self.AGENT]
        return dict_obs.flatten(obs, self.leaf_names) if self.dict_obs else obs

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> Any:
        """The task's own (vectorised) goal reward: what HER relabels transitions with."""
        if not self.box_goals:
            raise ConfigError(
                f"{self.env_id} has no Box goals to relabel (Kitchen nests one goal per task and "
                "its compute_reward updates episode state); HER needs Fetch, Hand or Maze."
            )
        return self.env.unwrapped.compute_reward(achieved_goal, desired_goal, info)  # type: ignore[attr-defined]

    @property
    def sim(self) -> MujocoSim:
        """The MuJoCo handle on the model simulated (Maze's and Kitchen's inner env)."""
        if self._sim is None:
            inner: Any = self.env.unwrapped
            for name in _INNER:
                inner = getattr(inner, name, inner)
            self._sim = MujocoSim(inner, getattr(inner, "fullpath", None))
        return self._sim
