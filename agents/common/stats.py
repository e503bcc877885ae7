"""What learners share: true-episode statistics of a run and SB3's `VecNormalize` wrapper.

`EpisodeStats` records the *true* return and cost of each finished episode (what the game puts
in ``infos``, never the disrupted reward) and drives a progress bar; `normalized` puts a VecEnv
under `VecNormalize`. The SB3 learners of `advgame.training`, the team and safe learners here,
and attacks that train (PA-AD's director) use both.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from advgame.errors import ConfigError

__all__ = ["EpisodeStats", "normalized"]


class EpisodeStats:
    """An SB3 callback factory recording true episode returns and driving a progress bar."""

    def __init__(self, progress: Any = None) -> None:
        self.progress = progress
        self.true_returns: list[float] = []
        self.true_costs: list[float] = []
        """True episode costs (recorded by learners on tasks with a cost)."""
        self.clipped = 0
        self.last_costs: list[float] = []
        """The true episode costs of the last `pop`."""

    def callback(self) -> Any:
        """A fresh SB3 `BaseCallback` feeding this recorder."""
        from stable_baselines3.common.callbacks import BaseCallback

        stats = self

        class _Callback(BaseCallback):
            def _init_callback(self) -> None:
                # per-env sums in Python floats: a numpy element update costs more than the add
                self._acc = [0.0] * self.training_env.num_envs
                self._cost = [0.0] * self.training_env.num_envs

            def _on_step(self) -> bool:
                infos, dones = self.locals["infos"], self.locals["dones"]
                acc, cost = self._acc, self._cost
                for i, info in enumerate(infos):
                    acc[i] += info.get("true_reward", 0.0)
                    cost[i] += info.get("true_cost", 0.0)
                    stats.clipped += int(info.get("clipped", 0))
                    if dones[i]:
                        stats.true_returns.append(float(acc[i]))
                        stats.true_costs.append(float(cost[i]))
                        acc[i] = cost[i] = 0.0
                if stats.progress is not None:
                    stats.progress.update(len(infos))
                return True

        return _Callback()

    def pop(self) -> tuple[float, int, int]:
        """Mean true return of finished episodes, episode count and clips since the last pop."""
        values, clipped = self.true_returns, self.clipped
        self.true_returns, self.clipped = [], 0
        self.last_costs, self.true_costs = self.true_costs, []
        return (float(np.mean(values)) if values else float("nan")), len(values), clipped


def normalized(venv: Any, normalize: bool, gamma: float) -> Any:
    """`venv` under SB3's `VecNormalize` (observations and rewards, discount `gamma`) if asked."""
    if not normalize:
        return venv
    from gymnasium import spaces
    from stable_baselines3.common.vec_env import VecNormalize

    if isinstance(venv.observation_space, spaces.Dict):
        raise ConfigError(
            f"normalize=True needs a Box observation, got {venv.observation_space}; goal-"
            "conditioned (Dict) protagonists train with TrainConfig(normalize=False)."
        )
    return VecNormalize(venv, norm_obs=True, norm_reward=True, gamma=gamma)
