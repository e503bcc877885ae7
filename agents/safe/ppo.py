"""The PPO core of the constrained learners: MAPPO/IPPO's pieces plus a cost critic.

PPO-Lagrangian, CRPO and PCRPO share everything here and differ only in how they combine the
reward and cost objectives (`Direction`):

* `SafeModel`: the IPPO `TeamModel` (an actor and a reward critic per protagonist) plus one cost
  critic per protagonist.
* `SafeCollector`: the `TeamCollector` that also records the cost each protagonist *observes*
  (after any cost disruptor: what the learner can know) and the cost critic's values.
* `safe_update`: PPO epochs over one rollout. The actor follows the clipped surrogate of the
  mixed advantage ``w_r·A_r - w_c·A_c`` (PPO-Lagrangian, CRPO), or, for PCRPO inside its slack
  band, the two surrogates' gradients projected onto each other's normal plane when they
  conflict and then weighted. Both critics regress on their GAE targets.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from advgame.agents.common.stats import EpisodeStats
from advgame.agents.marl.collect import TeamCollector
from advgame.agents.marl.nets import NumpyMLP, TeamModel, _mlp
from advgame.agents.marl.ppo import Rollout, TrainData, gae, kl_exceeded

__all__ = ["Direction", "SafeCollector", "SafeModel", "SafeTrainData", "project", "safe_update"]


class SafeModel(TeamModel):
    """IPPO's actors and reward critics, and one cost critic per protagonist."""

    def __init__(
        self,
        obs_dims: Mapping[str, int],
        act_dims: Mapping[str, int],
        hidden: Sequence[int],
        log_std_init: float,
        generator: torch.Generator,
    ) -> None:
        super().__init__(obs_dims, act_dims, None, hidden, log_std_init, generator)
        self.cost_critics = nn.ModuleDict(
            {a: _mlp([obs_dims[a], *hidden, 1], 1.0, generator) for a in self.agents}
        )

    def cost_values(self, obs: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """Each protagonist's cost-value estimate, ``[batch, agents]``."""
        return torch.cat([self.cost_critics[a](obs[a]) for a in self.agents], dim=-1)

    def numpy_cost_values(self) -> Any:
        """A numpy function ``obs -> [batch, agents]`` of the current cost critics."""
        nets = {a: NumpyMLP(self.cost_critics[a]) for a in self.agents}
        return lambda obs: np.concatenate([nets[a](obs[a]) for a in self.agents], axis=-1)

    def clip_grad_norms(self, max_norm: float) -> None:
        """Clip each actor's, reward critic's and cost critic's gradient norm separately."""
        super().clip_grad_norms(max_norm)
        for module in self.cost_critics.values():
            nn.utils.clip_grad_norm_(module.parameters(), max_norm)


@dataclass
class SafeTrainData(TrainData):
    """A rollout with the cost channel: cost advantages and cost-value targets."""

    cost_advantages: torch.Tensor | None = None
    """GAE advantages of the observed cost, ``[samples, agents]``."""
    cost_returns: torch.Tensor | None = None
    """Cost-value targets, ``[samples, agents]``."""


class SafeCollector(TeamCollector):
    """A `TeamCollector` that also records observed costs and cost values."""

    def collect(
        self, model: SafeModel, generator: torch.Generator, stats: EpisodeStats | None
    ) -> SafeTrainData:
        """``n_steps`` synchronous steps of every view; reward and cost advantages."""
        cfg, n_envs, n = self.config, len(self.envs), len(self.agents)
        self.finished_costs.clear()
        if self.obs is None:
            self.reset()
        net, cost_net = model.snapshot(), model.numpy_cost_values()
        noise = torch.randn((cfg.n_steps, n_envs, sum(self.act_dims.values())), generator=generator)
        splits = np.cumsum(list(self.act_dims.values()))[:-1]
        rollout = Rollout(self.obs_dims, self.act_dims, None, cfg.n_steps, n_envs)
        costs = np.zeros((cfg.n_steps, n_envs, n), np.float32)
        cost_values = np.zeros((cfg.n_steps, n_envs, n), np.float32)
        for t, step_noise in enumerate(noise.numpy()):
            obs = self.obs
            assert obs is not None
            actions, logp = net.sample(
                obs, dict(zip(self.agents, np.split(step_noise, splits, 1), strict=True))
            )
            values, cost_values[t] = net.values(obs, None), cost_net(obs)
            rewards, dones = self._step(net, actions, stats)
            costs[t] = self.costs[:, None]
            for e, (final, _) in self.cut.items():  # truncated: bootstrap the cost too
                costs[t, e] += cfg.cost_gamma * cost_net(final)[0]
            rollout.add(obs, None, actions, logp, values, rewards, dones)
        data = rollout.finish(net.values(self.obs, None), cfg.gamma, cfg.gae_lambda)
        adv, ret = gae(
            costs, cost_values, rollout.dones, cost_net(self.obs), cfg.cost_gamma, cfg.gae_lambda
        )
        return SafeTrainData(
            **vars(data),
            cost_advantages=torch.from_numpy(adv.reshape(-1, n)),
            cost_returns=torch.from_numpy(ret.reshape(-1, n)),
        )


@dataclass(frozen=True)
class Direction:
    """How one update combines the objectives: mixed advantages, or PCRPO's projection."""

    reward_weight: float
    """Weight of the reward surrogate (advantage or gradient)."""
    cost_weight: float
    """Weight of the cost-reducing surrogate."""
    project: bool = False
    """Combine the two surrogates' gradients, projected where they conflict (PCRPO)."""


def project(g_r: torch.Tensor, g_c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """PCRPO's gradient manipulation of the reward and cost gradients.

    If they conflict (negative inner product), each is projected onto the normal plane of the
    other; otherwise both are returned unchanged.
    """
    dot = torch.dot(g_r, g_c)
    if dot >= 0:
        return g_r, g_c
    return (
        g_r - dot / (g_c.dot(g_c) + 1e-12) * g_c,
        g_c - dot / (g_r.dot(g_r) + 1e-12) * g_r,
    )


def _standardize(x: torch.Tensor, on: bool) -> torch.Tensor:
    return (x - x.mean()) / (x.std() + 1e-8) if on and len(x) > 1 else x


def _surrogates(
    model: SafeModel, data: SafeTrainData, idx: torch.Tensor, cfg: Any
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Reward and cost-reducing surrogate losses, the critics' loss, and the entropy."""
    assert data.cost_advantages is not None and data.cost_returns is not None
    obs = {a: data.obs[a][idx] for a in model.agents}
    loss_r = loss_c = entropy = torch.zeros(())
    for i, agent in enumerate(model.agents):
        logp, ent = model.actor(agent).log_prob(obs[agent], data.actions[agent][idx])
        ratio = (logp - data.logp[idx, i]).exp()
        clipped = ratio.clamp(1 - cfg.clip_range, 1 + cfg.clip_range)
        for adv, sign in ((data.advantages[idx, i], 1.0), (data.cost_advantages[idx, i], -1.0)):
            a = sign * _standardize(adv, cfg.normalize_advantage)
            loss = -torch.min(ratio * a, clipped * a).mean()
            if sign > 0:
                loss_r = loss_r + loss
            else:
                loss_c = loss_c + loss
        entropy = entropy + ent
    critics = ((data.returns[idx] - model.values(obs, None)) ** 2).mean(0).sum()
    critics = critics + ((data.cost_returns[idx] - model.cost_values(obs)) ** 2).mean(0).sum()
    return loss_r, loss_c, critics, entropy


def _actor_gradient(
    model: SafeModel, loss_r: torch.Tensor, loss_c: torch.Tensor, way: Direction
) -> None:
    """Add PCRPO's combined, projected actor gradient to the actors' ``.grad``."""
    params = [p for p in model.actors.parameters() if p.requires_grad]
    g_r = torch.cat([g.flatten() for g in torch.autograd.grad(loss_r, params, retain_graph=True)])
    g_c = torch.cat([g.flatten() for g in torch.autograd.grad(loss_c, params, retain_graph=True)])
    g_r, g_c = project(g_r, g_c)
    combined = way.reward_weight * g_r + way.cost_weight * g_c
    start = 0
    for p in params:
        part = combined[start : start + p.numel()].view_as(p)
        p.grad = part.clone() if p.grad is None else p.grad + part
        start += p.numel()


def safe_update(
    model: SafeModel,
    optimizer: torch.optim.Optimizer,
    data: SafeTrainData,
    cfg: Any,
    generator: torch.Generator,
    way: Direction,
) -> dict[str, float]:
    """`cfg.n_epochs` passes of minibatch updates in direction `way`; mean diagnostics.

    Fewer epochs run when `cfg.target_kl` stops them; the count is in the diagnostics.
    """
    n = len(data.logp)
    total, count, epochs = torch.zeros(4), 0, 0
    for _ in range(cfg.n_epochs):
        if epochs and kl_exceeded(model, data.obs, data.actions, data.logp, cfg.target_kl):
            break
        epochs += 1
        order = torch.randperm(n, generator=generator)
        for start in range(0, n, cfg.batch_size):
            idx = order[start : start + cfg.batch_size]
            loss_r, loss_c, critics, entropy = _surrogates(model, data, idx, cfg)
            optimizer.zero_grad()
            if way.project:
                _actor_gradient(model, loss_r, loss_c, way)
                rest = cfg.vf_coef * critics - cfg.ent_coef * entropy
            else:
                mixed = way.reward_weight * loss_r + way.cost_weight * loss_c
                rest = mixed + cfg.vf_coef * critics - cfg.ent_coef * entropy
            rest.backward()
            model.clip_grad_norms(cfg.max_grad_norm)
            optimizer.step()
            parts = torch.stack([loss_r, loss_c, critics, entropy]).detach()
            total, count = total + parts, count + 1
    names = ("reward_surrogate", "cost_surrogate", "critic_loss", "entropy")
    return {**dict(zip(names, (total / max(count, 1)).tolist(), strict=True)), "epochs": epochs}
