"""DBC (Zhang et al., ICLR 2021): Deep Bisimulation for Control on Stable-Baselines3's SAC.

DBC trains an encoder ``z = φ(s)`` so that distances between encodings follow a bisimulation
metric: two states are close when they give close rewards and close distributions of next
encodings, whatever else differs between them (a distractor that changes neither is encoded
away). This module follows the authors' code (``facebookresearch/deep_bisim4control``:
``agent/bisim_agent.py``, ``transition_model.py``), re-built on SB3's SAC (its squashed
Gaussian, twin critics, temperature, replay buffer, save/load, logging and callbacks stay
SB3's); the networks are `advgame.agents.dbc.nets.DBCPolicy`'s. Each update, in the authors'
order:

* **Critic**: ``Σ_k mean((Q_k(φ(s), a) − y)²)`` with
  ``y = r + γ (1 − d) [min_k Q̄_k(φ̄(s'), a') − α log π(a'|s')]``, ``a' ~ π(·|φ(s'))``; its
  gradient trains the Q networks *and the encoder* (the critic's optimizer holds both).
* **Model and encoder**: ``bisim_coef · J_bisim + J_transition + J_reward``, one backward
  pass, a step of the encoder's optimizer and of the decoder's (transition model and reward
  decoder), with

  - ``J_transition = mean(½ ((μ(z, a) − sg(φ(s'))) / σ(z, a))² + log σ(z, a))`` (`transition_loss`),
  - ``J_reward = mean((R̂(μ + σ·ε) − r)²)``, ``ε ~ N(0, 1)`` (`reward_loss`),
  - ``J_bisim = mean((|z − z_π|_h − (|r − r_π|_h + γ·W))²)`` (`bisimulation_loss`) over a random
    permutation π of the batch, element by element over the encoding's dimensions, where
    ``|·|_h`` is the smooth-L1 (Huber, δ = 1) distance, ``W = √((μ − μ_π)² + (σ − σ_π)²)``
    the 2-Wasserstein distance of the predicted next-encoding Gaussians per dimension, and
    ``μ, σ`` computed without gradient: only ``z`` and ``z_π`` carry the encoder's gradient.

* **Actor and temperature** every `actor_update_interval`-th update: SAC's actor loss on the
  detached encoding, then the authors' temperature loss ``α·(−log π − H̄)``.
* **Targets** every `target_update_interval`-th update: the Q networks at `tau`, the target
  encoder at `encoder_tau`.

What differs from the authors' code, and why, is in docs/causal.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.utils import polyak_update, update_learning_rate
from torch.nn import functional as F

from advgame.agents.dbc.nets import DBCPolicy

__all__ = ["DBC", "bisimulation_loss", "reward_loss", "transition_loss"]


def bisimulation_loss(
    z: th.Tensor,
    rewards: th.Tensor,
    mu: th.Tensor,
    sigma: th.Tensor,
    perm: th.Tensor,
    gamma: float,
) -> th.Tensor:
    """``mean((|z − z_π|_h − |r − r_π|_h − γ·√((μ − μ_π)² + (σ − σ_π)²))²)``, per dimension.

    `z` are the encodings (with gradient), `rewards` ``[n, 1]``, `mu` and `sigma` the
    transition model's prediction for the batch (without gradient), `perm` the pairing.
    """
    z_dist = F.smooth_l1_loss(z, z[perm], reduction="none")
    r_dist = F.smooth_l1_loss(rewards, rewards[perm], reduction="none")
    w2 = th.sqrt((mu - mu[perm]).pow(2) + (sigma - sigma[perm]).pow(2))
    return (z_dist - (r_dist + gamma * w2)).pow(2).mean()


def transition_loss(mu: th.Tensor, sigma: th.Tensor, next_z: th.Tensor) -> th.Tensor:
    """The Gaussian negative log-likelihood (less its constant) of `next_z` under ``N(μ, σ²)``."""
    diff = (mu - next_z) / sigma
    return (0.5 * diff.pow(2) + th.log(sigma)).mean()


def reward_loss(predicted: th.Tensor, rewards: th.Tensor) -> th.Tensor:
    """Mean squared error of the reward decoder's prediction."""
    return F.mse_loss(predicted, rewards)


class DBC(SAC):
    """SB3's SAC with DBC's encoder and losses (see the module docstring for the formulas).

    Defaults: the Robust Gymnasium paper's DBC parameters and the authors' code. The network
    sizes and the encoder's and decoder's rates are `DBCPolicy`'s keywords (``policy_kwargs``).

    Args beyond SAC's:
        bisim_coef: weight of the bisimulation loss (paper: 0.5).
        encoder_tau: the target encoder's update rate (authors: 0.005).
        actor_update_interval: updates between actor and temperature updates (authors: 2).
        critic_learning_rate: the Adam rate of the critic's step (Q networks and encoder).

    A `critic_learning_rate` of None is `learning_rate`; either follows the shape of
    `learning_rate`'s schedule.
    """

    policy: DBCPolicy

    def __init__(
        self,
        policy: Any,
        env: Any,
        *,
        bisim_coef: float = 0.5,
        encoder_tau: float = 0.005,
        actor_update_interval: int = 2,
        critic_learning_rate: float | None = None,
        _init_setup_model: bool = True,
        **kwargs: Any,
    ) -> None:
        if not bisim_coef >= 0:
            raise ValueError(f"DBC's bisim_coef must be >= 0, got {bisim_coef!r}.")
        self.bisim_coef, self.encoder_tau = bisim_coef, encoder_tau
        self.actor_update_interval = actor_update_interval
        self.critic_learning_rate = critic_learning_rate
        self.counts = {"critic": 0, "model": 0, "actor": 0, "target": 0}
        """Updates done so far, by step of the schedule (the tests count them)."""
        if policy == "MlpPolicy":
            policy = DBCPolicy
        super().__init__(policy, env, _init_setup_model=False, **kwargs)
        if _init_setup_model:
            self._setup_model()

    @property
    def encoder(self) -> Any:
        """φ, the critic's encoder (`advgame.agents.dbc.nets.BisimEncoder`)."""
        return self.policy.encoder

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts, tensors = super()._get_torch_save_params()
        extra = ["policy.encoder_optimizer", "policy.decoder_optimizer"]
        return [*state_dicts, *extra], tensors

    # -- the losses on a batch ----------------------------------------------------------------

    def critic_loss(self, data: Any, alpha: th.Tensor) -> th.Tensor:
        """SAC's twin-critic loss through the encoder, the target from the target encoder."""
        discounts = getattr(data, "discounts", None)
        discounts = self.gamma if discounts is None else discounts
        with th.no_grad():
            next_actions, next_log_prob = self.actor.action_log_prob(data.next_observations)
            targ = th.cat(self.critic_target(data.next_observations, next_actions), dim=1)
            low = th.min(targ, dim=1, keepdim=True)[0] - alpha * next_log_prob.reshape(-1, 1)
            target = data.rewards + (1 - data.dones) * discounts * low
        current = self.critic(data.observations, data.actions)
        return sum((F.mse_loss(q, target) for q in current), th.zeros(()))

    def model_losses(
        self, data: Any, perm: th.Tensor | None = None, noise: th.Tensor | None = None
    ) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        """``(J_bisim, J_transition, J_reward)`` on a batch.

        `perm` pairs the rows of the bisimulation loss and `noise` is the ε of the reward
        decoder's sample (both drawn from torch's generator when None).
        """
        policy = self.policy
        z = policy.encode(data.observations)
        mu, sigma = policy.transition_model(z, data.actions.float())
        with th.no_grad():
            next_z = policy.encode(data.next_observations)
        noise = th.randn_like(sigma) if noise is None else noise
        predicted = policy.reward_decoder(mu + sigma * noise)
        perm = th.randperm(len(z), device=z.device) if perm is None else perm
        bisim = bisimulation_loss(z, data.rewards, mu.detach(), sigma.detach(), perm, self.gamma)
        return bisim, transition_loss(mu, sigma, next_z), reward_loss(predicted, data.rewards)

    # -- the updates --------------------------------------------------------------------------

    def _alpha(self) -> th.Tensor:
        if self.log_ent_coef is not None:
            return th.exp(self.log_ent_coef.detach())
        return self.ent_coef_tensor

    def _update_rates(self) -> None:
        """Actor and temperature on the schedule; the critic on it, scaled to its own rate."""
        optimizers = [self.actor.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers.append(self.ent_coef_optimizer)
        self._update_learning_rate(optimizers)
        rate = self.lr_schedule(self._current_progress_remaining)
        if self.critic_learning_rate is not None:
            first = getattr(self.learning_rate, "initial", self.learning_rate)
            first = float(first(1.0) if callable(first) else first)
            rate = self.critic_learning_rate * (rate / first if first > 0 else 1.0)
        update_learning_rate(self.critic.optimizer, rate)

    def critic_step(self, data: Any) -> float:
        """One step of the critic's optimizer (Q networks and encoder) on `critic_loss`."""
        loss = self.critic_loss(data, self._alpha())
        self.critic.optimizer.zero_grad()
        loss.backward()
        self.critic.optimizer.step()
        self.counts["critic"] += 1
        return float(loss.item())

    def model_step(self, data: Any) -> tuple[float, float, float]:
        """One step of the encoder's and decoder's optimizers on the model losses.

        The loss is ``bisim_coef·J_bisim + J_transition + J_reward``; returns the three terms.
        """
        policy = self.policy
        bisim, trans, reward = self.model_losses(data)
        policy.encoder_optimizer.zero_grad()
        policy.decoder_optimizer.zero_grad()
        (self.bisim_coef * bisim + trans + reward).backward()
        policy.encoder_optimizer.step()
        policy.decoder_optimizer.step()
        self.counts["model"] += 1
        return float(bisim.item()), float(trans.item()), float(reward.item())

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        """`gradient_steps` DBC updates: critic, model and encoder, then actor and targets."""
        self.policy.set_training_mode(True)
        self._update_rates()
        logs: dict[str, list[float]] = {"critic": [], "bisim": [], "transition": [], "reward": []}
        actor_losses = []
        for _ in range(gradient_steps):
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            losses = (self.critic_step(data), *self.model_step(data))
            for key, value in zip(logs, losses, strict=True):
                logs[key].append(value)
            if self._n_updates % self.actor_update_interval == 0:
                actor_losses.append(self._actor_step(data.observations))
            if self._n_updates % self.target_update_interval == 0:
                self._update_targets()
            self._n_updates += 1
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        for key, values in logs.items():
            self.logger.record(f"train/{key}_loss", float(np.mean(values)))
        if actor_losses:
            self.logger.record("train/actor_loss", float(np.mean(actor_losses)))
        self.logger.record("train/ent_coef", float(self._alpha().item()))

    def _actor_step(self, obs: th.Tensor) -> float:
        """SAC's actor loss on the detached encoding, then the authors' temperature loss."""
        alpha = self._alpha()
        critic = list(self.critic.parameters())
        for p in critic:  # the actor's gradient only: nothing flows into critic or encoder
            p.requires_grad_(False)
        try:
            actions, log_prob = self.actor.action_log_prob(obs)
            log_prob = log_prob.reshape(-1, 1)
            q = th.min(th.cat(self.critic(obs, actions), dim=1), dim=1, keepdim=True)[0]
            loss = (alpha * log_prob - q).mean()
            self.actor.optimizer.zero_grad()
            loss.backward()
        finally:
            for p in critic:
                p.requires_grad_(True)
        self.actor.optimizer.step()
        self.counts["actor"] += 1
        if self.ent_coef_optimizer is not None and self.log_ent_coef is not None:
            assert isinstance(self.target_entropy, float)
            gap = (-log_prob - self.target_entropy).detach()
            ent_loss = (th.exp(self.log_ent_coef) * gap).mean()
            self.ent_coef_optimizer.zero_grad()
            ent_loss.backward()
            self.ent_coef_optimizer.step()
        return float(loss.item())

    def _update_targets(self) -> None:
        """Q networks towards the critic's at `tau`, the target encoder at `encoder_tau`."""
        online = [p for net in self.critic.q_networks for p in net.parameters()]
        target = [p for net in self.critic_target.q_networks for p in net.parameters()]
        polyak_update(online, target, self.tau)
        polyak_update(
            self.policy.encoder.parameters(),
            self.policy.target_encoder.parameters(),
            self.encoder_tau,
        )
        self.counts["target"] += 1
