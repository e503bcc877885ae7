"""Experience for MAPPO and IPPO: team views stepped in sync in this process.

`TeamCollector` owns the `TeamView`s, the running normalizer of what the learners see (every
protagonist's observation and, for MAPPO's critic, the global state), the reward scaler, and the
episodes in flight. `TeamCollector.collect` plays ``n_steps`` synchronous steps of every view
with a numpy snapshot of the current networks and returns the finished rollout.

The observation normalizer is one `RunningNorm` over the concatenation ``[obs_0 | obs_1 | ... |
state]``: its statistics are per component, so this is the same as one normalizer per agent
(and one for the state), updated with one call per step instead of one per agent.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from gymnasium import spaces

from advgame.agents.common.stats import EpisodeStats
from advgame.agents.marl.nets import TeamModel, TeamSnapshot
from advgame.agents.marl.norm import RewardScaler, RunningNorm
from advgame.agents.marl.ppo import Rollout, TrainData
from advgame.errors import ConfigError

__all__ = ["TeamCollector"]


class TeamCollector:
    """Steps team views in sync; normalizes observations, states and rewards while training.

    Args:
        envs: team views (`advgame.core.team.TeamView`) of one game (the same protagonists).
        config: the learner config (``n_steps``, ``gamma``, normalization switches, ``clip_obs``).
        rng: draws the seed of every episode of every view (the learner's generator).

    """

    def __init__(self, envs: Sequence[Any], config: Any, rng: np.random.Generator) -> None:
        self.envs = list(envs)
        self.agents: list[str] = list(self.envs[0].possible_agents)
        self.config = config
        self.rng = rng
        self.training = True
        """Whether the normalizers update (`TeamLearner.freeze` stops them)."""
        first = self.envs[0]
        self._check(first)
        self.obs_dims = {a: first.observation_space(a).shape[0] for a in self.agents}
        self.act_dims = {a: first.action_space(a).shape[0] for a in self.agents}
        self.state_dim: int | None = first.state_space.shape[0] if config.centralised else None
        self.bounds = {
            a: (first.action_space(a).low, first.action_space(a).high) for a in self.agents
        }
        sizes = [*self.obs_dims.values(), self.state_dim or 0]
        ends = np.cumsum(sizes).tolist()
        self.slices = {
            k: slice(e - n, e) for k, n, e in zip([*self.agents, "state"], sizes, ends, strict=True)
        }
        self.norm = (
            RunningNorm((ends[-1],), config.clip_obs) if config.normalize_observations else None
        )
        self.reward_scaler = (
            RewardScaler(len(self.envs), len(self.agents), config.gamma, config.clip_obs)
            if config.normalize_reward
            else None
        )
        self.obs: dict[str, np.ndarray] | None = None
        """Normalized current observations per agent, ``[envs, obs_dim]`` (None before reset)."""
        self.state: np.ndarray | None = None
        """Normalized current global states ``[envs, state_dim]`` (MAPPO only)."""
        self._returns = np.zeros(len(self.envs))  # true team return of each episode in flight
        self._costs = np.zeros((2, len(self.envs)))  # true and observed cost of each episode
        self.costs = np.zeros(len(self.envs), np.float32)
        """The cost each view's first protagonist observed on the last step (after disruptors)."""
        self.finished_costs: list[float] = []
        """Observed cost of each episode finished in the last rollout (`collect`)."""
        self.cut: dict[int, tuple[Any, Any]] = {}
        """Views truncated on the last step: their final normalized observations and state."""

    def _check(self, first: Any) -> None:
        for env in self.envs[1:]:
            if list(env.possible_agents) != self.agents:
                raise ConfigError(
                    f"Team views disagree on agents: {env.possible_agents} vs {self.agents}."
                )
        boxes = [first.observation_space(a) for a in self.agents]
        boxes += [first.action_space(a) for a in self.agents]
        if self.config.centralised:
            boxes.append(first.state_space)
        for space in boxes:
            if not isinstance(space, spaces.Box) or len(space.shape) != 1:
                raise ConfigError(
                    f"{self.config.algo.upper()} here needs flat Box observations, states and "
                    f"actions; got {space}. Flatten the task's spaces or use an SB3 learner."
                )

    def collect(
        self, model: TeamModel, generator: torch.Generator, stats: EpisodeStats | None
    ) -> TrainData:
        """``n_steps`` synchronous steps of every view with `model`'s actors.

        Returns the rollout with its advantages and returns, ready for `ppo_update`.
        """
        cfg, n_envs = self.config, len(self.envs)
        self.finished_costs.clear()
        if self.obs is None:
            self.reset()
        net = model.snapshot()
        noise = torch.randn((cfg.n_steps, n_envs, sum(self.act_dims.values())), generator=generator)
        splits = np.cumsum(list(self.act_dims.values()))[:-1]
        rollout = Rollout(self.obs_dims, self.act_dims, self.state_dim, cfg.n_steps, n_envs)
        for step_noise in noise.numpy():
            obs, state = self.obs, self.state
            assert obs is not None
            actions, logp = net.sample(
                obs, dict(zip(self.agents, np.split(step_noise, splits, 1), strict=True))
            )
            values = net.values(obs, state)
            rewards, dones = self._step(net, actions, stats)
            rollout.add(obs, state, actions, logp, values, rewards, dones)
        return rollout.finish(net.values(self.obs, self.state), cfg.gamma, cfg.gae_lambda)

    def reset(self) -> None:
        """Start a fresh, seeded episode in every view."""
        raw, states = [], []
        for env in self.envs:
            obs, _ = env.reset(seed=self._episode_seed())
            raw.append(obs)
            states.append(env.state())
        self._returns[:] = 0.0
        self._costs[:] = 0.0
        self.obs, self.state = self._normalized(raw, states, update=self.training)

    def normalize(self, agent: str, observation: Any) -> np.ndarray:
        """`agent`'s normalized view of one raw observation, ``[1, obs_dim]`` (no update)."""
        x = np.asarray(observation, dtype=np.float64)[None]
        if self.norm is None:
            return x.astype(np.float32)
        return self.norm.subset(self.slices[agent]).normalize(x)

    def observation_norms(self) -> dict[str, RunningNorm]:
        """Each agent's observation normalizer (copies), or {} when unnormalized."""
        norm = self.norm
        return {} if norm is None else {a: norm.subset(self.slices[a]) for a in self.agents}

    def _step(
        self, net: TeamSnapshot, actions: Mapping[str, np.ndarray], stats: EpisodeStats | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Step every view, resetting finished ones; the current observations advance.

        Returns the rewards ``[envs, agents]`` (scaled; a truncated episode's last reward
        bootstrapped with the value of its final state) and the episode ends ``[envs]``.
        """
        first = self.agents[0]
        raw, states = [], []
        rewards = np.zeros((len(self.envs), len(self.agents)))
        dones = np.zeros(len(self.envs), bool)
        cut: dict[int, tuple[Any, Any]] = {}  # truncated views: final observations and state
        for e, env in enumerate(self.envs):
            act = {a: np.clip(actions[a][e], *self.bounds[a]) for a in self.agents}
            obs, rew, term, _, infos = env.step(act)
            rewards[e] = [rew[a] for a in self.agents]
            self._returns[e] += infos[first]["true_reward"]
            self.costs[e] = infos[first]["cost"]
            self._costs[:, e] += (infos[first]["true_cost"], infos[first]["cost"])
            if not env.agents:
                dones[e] = True
                if stats is not None:
                    stats.true_returns.append(float(self._returns[e]))
                    stats.true_costs.append(float(self._costs[0, e]))
                self.finished_costs.append(float(self._costs[1, e]))
                self._returns[e], self._costs[:, e] = 0.0, 0.0
                if not term[first]:
                    cut[e] = (obs, env.state())
                obs, _ = env.reset(seed=self._episode_seed())
            raw.append(obs)
            states.append(env.state() if self.state_dim else None)
        if stats is not None and stats.progress is not None:
            stats.progress.update(len(self.envs))
        self.obs, self.state = self._normalized(raw, states, update=self.training)
        if self.reward_scaler is not None:
            rewards = self.reward_scaler(rewards, dones, update=self.training)
        self.cut = {e: self._normalized([o], [s], update=False) for e, (o, s) in cut.items()}
        for e, final in self.cut.items():
            rewards[e] += self.config.gamma * net.values(*final)[0]
        return rewards, dones

    def _episode_seed(self) -> int:
        return int(self.rng.integers(2**31 - 1))

    def _normalized(
        self, raw: list[dict[str, Any]], states: list[Any], update: bool
    ) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
        """Concatenate each view's observations (and state), normalize, split per agent."""
        parts = [np.stack([np.asarray(o[a], dtype=np.float64) for o in raw]) for a in self.agents]
        if self.state_dim is not None:
            parts.append(np.stack([np.asarray(s, dtype=np.float64) for s in states]))
        x = np.concatenate(parts, axis=1)
        if self.norm is None:
            x = x.astype(np.float32)
        else:
            if update:
                self.norm.update(x)
            x = self.norm.normalize(x)
        obs = {a: x[:, self.slices[a]] for a in self.agents}
        return obs, (x[:, self.slices["state"]] if self.state_dim is not None else None)

    def state_dict(self) -> dict[str, Any]:
        """The normalizers' statistics (for checkpoints)."""
        rewards = self.reward_scaler
        return {
            "observations": None if self.norm is None else self.norm.state_dict(),
            "rewards": None if rewards is None else rewards.rms.state_dict(),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore statistics written by `state_dict`."""
        if self.norm is not None:
            self.norm.load_state_dict(state["observations"])
        if self.reward_scaler is not None:
            self.reward_scaler.rms.load_state_dict(state["rewards"])

    def close(self) -> None:
        """Close the views."""
        for env in self.envs:
            env.close()
