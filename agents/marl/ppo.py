"""The PPO core shared by MAPPO and IPPO: the rollout store, GAE, the clipped loss, the update.

Every array is indexed ``[step, env, ...]`` while collecting and flattened to ``[sample, ...]`` for
the update. Per-agent quantities (log-probabilities, values, rewards, advantages) carry a last
axis over the protagonists, in team order. The algorithms differ only in their critic
(`TeamModel.values`); everything here is the same for both.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from advgame.agents.marl.nets import TeamModel

__all__ = ["Rollout", "TrainData", "gae", "kl_exceeded", "ppo_update"]


def gae(
    rewards: np.ndarray,
    values: np.ndarray,
    dones: np.ndarray,
    last_values: np.ndarray,
    gamma: float,
    lam: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Generalized advantage estimates and value targets.

    Args:
        rewards: ``[steps, envs, agents]``, as the learners observed them (scaled).
        values: ``[steps, envs, agents]``, the critic's estimates.
        dones: ``[steps, envs]``; ``dones[t]`` means the episode ended with step ``t`` (a
            truncated episode's bootstrap value is already folded into its last reward).
        last_values: ``[envs, agents]``, the values of the observations after the last step.
        gamma: the discount.
        lam: GAE λ.

    Returns:
        ``(advantages, returns)``, both ``[steps, envs, agents]``.

    """
    advantages = np.zeros_like(values)
    running = np.zeros_like(last_values)
    for t in reversed(range(len(rewards))):
        next_values = last_values if t == len(rewards) - 1 else values[t + 1]
        alive = 1.0 - dones[t].astype(values.dtype)[:, None]
        delta = rewards[t] + gamma * next_values * alive - values[t]
        running = delta + gamma * lam * alive * running
        advantages[t] = running
    return advantages, advantages + values


class Rollout:
    """What one rollout of `n_steps` synchronous steps of `n_envs` team views records."""

    def __init__(
        self,
        obs_dims: Mapping[str, int],
        act_dims: Mapping[str, int],
        state_dim: int | None,
        n_steps: int,
        n_envs: int,
    ) -> None:
        shape, n = (n_steps, n_envs), len(obs_dims)
        self.agents = list(obs_dims)
        self.obs = {a: np.zeros((*shape, d), np.float32) for a, d in obs_dims.items()}
        self.actions = {a: np.zeros((*shape, d), np.float32) for a, d in act_dims.items()}
        self.states = None if state_dim is None else np.zeros((*shape, state_dim), np.float32)
        self.logp = np.zeros((*shape, n), np.float32)
        self.values = np.zeros((*shape, n), np.float32)
        self.rewards = np.zeros((*shape, n), np.float32)
        self.dones = np.zeros(shape, bool)
        self.t = 0

    def add(
        self,
        obs: Mapping[str, np.ndarray],
        states: np.ndarray | None,
        actions: Mapping[str, np.ndarray],
        logp: np.ndarray,
        values: np.ndarray,
        rewards: np.ndarray,
        dones: np.ndarray,
    ) -> None:
        """Record the next step (every argument ``[envs, ...]``; dicts are per agent)."""
        t = self.t
        for a in self.agents:
            self.obs[a][t] = obs[a]
            self.actions[a][t] = actions[a]
        if self.states is not None:
            self.states[t] = states
        self.logp[t], self.values[t], self.rewards[t], self.dones[t] = logp, values, rewards, dones
        self.t += 1

    def finish(self, last_values: np.ndarray, gamma: float, lam: float) -> TrainData:
        """Advantages and returns, everything flattened to samples, as tensors."""
        advantages, returns = gae(self.rewards, self.values, self.dones, last_values, gamma, lam)

        def flat(x: np.ndarray) -> torch.Tensor:
            return torch.from_numpy(x.reshape(-1, *x.shape[2:]))

        return TrainData(
            obs={a: flat(self.obs[a]) for a in self.agents},
            actions={a: flat(self.actions[a]) for a in self.agents},
            states=None if self.states is None else flat(self.states),
            logp=flat(self.logp),
            advantages=flat(advantages),
            returns=flat(returns),
        )


@dataclass
class TrainData:
    """One rollout flattened to samples (``[samples, ...]`` tensors)."""

    obs: dict[str, torch.Tensor]
    """Normalized observations per agent."""
    actions: dict[str, torch.Tensor]
    """Actions as sampled (before clipping into the action space) per agent."""
    states: torch.Tensor | None
    """Normalized global states (MAPPO) or None (IPPO)."""
    logp: torch.Tensor
    """Log-probabilities of the actions when sampled, ``[samples, agents]``."""
    advantages: torch.Tensor
    """GAE advantages, ``[samples, agents]``."""
    returns: torch.Tensor
    """Value targets, ``[samples, agents]``."""


def _loss(
    model: TeamModel, data: TrainData, idx: torch.Tensor, cfg: Any
) -> tuple[torch.Tensor, torch.Tensor]:
    """The PPO loss of one minibatch, and its diagnostics [policy, value, entropy, kl, clipped]."""
    policy_loss = entropy = kl = clipped = torch.zeros(())
    obs = {a: data.obs[a][idx] for a in model.agents}
    for i, agent in enumerate(model.agents):
        logp, agent_entropy = model.actor(agent).log_prob(obs[agent], data.actions[agent][idx])
        log_ratio = logp - data.logp[idx, i]
        ratio = log_ratio.exp()
        adv = data.advantages[idx, i]
        if cfg.normalize_advantage and len(adv) > 1:
            adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        surrogate = torch.min(
            ratio * adv, ratio.clamp(1 - cfg.clip_range, 1 + cfg.clip_range) * adv
        )
        policy_loss = policy_loss - surrogate.mean()
        entropy = entropy + agent_entropy
        with torch.no_grad():
            kl = kl + ((ratio - 1) - log_ratio).mean()
            clipped = clipped + ((ratio - 1).abs() > cfg.clip_range).float().mean()
    states = None if data.states is None else data.states[idx]
    value_loss = ((data.returns[idx] - model.values(obs, states)) ** 2).mean(0).sum()
    loss = policy_loss - cfg.ent_coef * entropy + cfg.vf_coef * value_loss
    n = len(model.agents)
    parts = torch.stack([policy_loss, value_loss, entropy / n, kl / n, clipped / n]).detach()
    return loss, parts


def kl_exceeded(
    model: TeamModel,
    obs: Mapping[str, torch.Tensor],
    actions: Mapping[str, torch.Tensor],
    logp: torch.Tensor,
    target_kl: float | None,
) -> bool:
    """Whether any actor has moved more than `target_kl` from the rollout's policy.

    The KL is estimated over the whole rollout as the mean of ``(r - 1) - log r`` (``r`` the
    probability ratio of the sampled actions; never negative, unbiased for KL(old ‖ new)).
    """
    if target_kl is None:
        return False
    with torch.no_grad():
        for i, agent in enumerate(model.agents):
            new, _ = model.actor(agent).log_prob(obs[agent], actions[agent])
            log_ratio = new - logp[:, i]
            if float((log_ratio.exp() - 1 - log_ratio).mean()) > target_kl:
                return True
    return False


def ppo_update(
    model: TeamModel,
    optimizer: torch.optim.Optimizer,
    data: TrainData,
    cfg: Any,
    generator: torch.Generator,
) -> dict[str, float]:
    """`cfg.n_epochs` passes of clipped-surrogate minibatch updates over one rollout.

    Each minibatch updates every actor on its own surrogate (its own advantages) and the
    critic(s) on every agent's value targets; gradients are clipped per network. Returns the
    mean diagnostics: policy and value loss (summed over agents), entropy, approximate KL and
    clip fraction (averaged over agents), and the epochs run (fewer than `cfg.n_epochs` when
    `cfg.target_kl` stopped them).
    """
    n = len(data.logp)
    total, count, epochs = torch.zeros(5), 0, 0
    for _ in range(cfg.n_epochs):
        if epochs and kl_exceeded(model, data.obs, data.actions, data.logp, cfg.target_kl):
            break
        epochs += 1
        order = torch.randperm(n, generator=generator)
        for start in range(0, n, cfg.batch_size):
            loss, parts = _loss(model, data, order[start : start + cfg.batch_size], cfg)
            optimizer.zero_grad()
            loss.backward()
            model.clip_grad_norms(cfg.max_grad_norm)
            optimizer.step()
            total, count = total + parts, count + 1
    names = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction")
    return {**dict(zip(names, (total / max(count, 1)).tolist(), strict=True)), "epochs": epochs}
