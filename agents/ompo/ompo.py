"""OMPO (Luo et al., ICML 2024): occupancy-matching policy optimisation on Stable-Baselines3's SAC.

OMPO learns under shifting dynamics by correcting the reward with a discriminator between the
*local* transitions (the latest ones, from the current dynamics) and the *global* replay (every
dynamics seen), and by a DICE-style critic with a power loss and an initial-state term. This
module follows the authors' code (``Roythuly/OMPO``: ``model/algo.py``, ``model/discriminator.py``,
``main_non_stationary.py``), re-built on SB3's SAC (its actor, twin critics, targets, entropy
tuning, replay buffer, save/load, logging and callbacks stay SB3's):

* **Discriminator** on ``(s, a, s')``: a tanh MLP (hidden 256, Adam 3e-4), trained each time
  `local_size` new transitions have arrived (``disc_rounds`` rounds: a draw of `local_size`
  global transitions, then ``disc_updates`` updates of ``disc_batch`` local (label 1) against
  ``disc_batch`` of that draw (label 0)), binary cross-entropy plus a gradient penalty
  ``λ (‖∇D(x̂)‖ − 1)²`` on random interpolations ``x̂``. Its logit estimates
  ``log ρ_local / ρ_global``.
* **Reward**: ``r' = max(r + reward_max, 1e-6) − w · logit D(s, a, s')``, ``w`` the
  `correction_weight` (None: `tomac_alpha`, the authors'; 0: none, the initial-state terms keep
  `tomac_alpha`). Each training call logs ``train/logit_abs`` (mean ``|logit|``),
  ``train/correction_abs`` (``w ·`` that) and ``train/correction_ratio`` (over the shifted reward).
* **Critic** (every update): for each critic k, the target
  ``y_k = r' + γ (1 − d) [mix · Q_k(s', a') + (1 − mix) · min_j Q̄_j(s', a') − α log π(a'|s')]``
  (``a' ~ π(s')``, `critic_mix` 0.05 of the online critic) and the loss
  ``Σ_k mean(|y_k − Q_k(s, a)|^p / p + (1 − γ) · tomac_alpha · Q_k(s₀, π(s₀)))``
  with ``p`` = `exponent` (1.5) and ``s₀`` drawn from the episodes' first states.
* **Actor** (every `target_update_interval`-th update): no SAC ``Q(s, π(s))`` term; the loss is
  ``−½ Σ_k mean(g(y_k − Q_k) · (y_k − Q_k) + (1 − γ) · tomac_alpha · Q_k(s₀, π(s₀)))`` with
  ``g(x) = clip(x, 0)^{p−1}`` held constant, the gradient reaching the policy through
  ``a' ~ π(s')``, ``log π(a'|s')`` and ``π(s₀)``. Then the entropy temperature (SAC's rule) and
  the soft target update.

Where this differs from the authors' code, and why (also in docs/ompo.md):

* The initial-state buffer holds every episode's first state, drawn with replacement; the
  authors also push 256 extra resets before training (with a Hopper they come from the nominal
  body), which only exists so that a first batch can be drawn without replacement.
* The temperature starts at `ent_coef`'s value (``"auto_0.2"``: the paper's table says α 0.2
  with automatic tuning); the authors' code uses 0.2 for the very first critic and actor
  update and then ``exp(log α)`` from ``log α = 0``, i.e. α = 1.
* Rewards are whatever the views give (VecNormalize's if the run normalises); OMPO's ``+1``
  shift and clamp assume raw rewards, so its campaigns train with ``normalize = false``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.utils import polyak_update
from torch import nn
from torch.nn import functional as F

from advgame.agents.common.replay_store import filled
from advgame.agents.ompo.nets import OMPOPolicy, SigmoidTanh

__all__ = ["OMPO", "OMPOReplayBuffer", "TransitionDiscriminator"]


class TransitionDiscriminator(nn.Module):
    """D(s, a, s'): a tanh MLP whose logit estimates ``log ρ_local(s, a, s') / ρ_global(s, a, s')``."""

    def __init__(self, inputs: int, hidden: int = 256, lr: float = 3e-4, penalty: float = 10.0):
        super().__init__()
        self.trunk = nn.Sequential(
            nn.Linear(inputs, hidden), SigmoidTanh(), nn.Linear(hidden, hidden), SigmoidTanh(),
            nn.Linear(hidden, 1),
        )  # fmt: skip
        self.penalty = penalty
        """λ of the gradient penalty."""
        self.optimizer = th.optim.Adam(self.trunk.parameters(), lr=lr, fused=True)

    def forward(self, x: th.Tensor) -> th.Tensor:
        """The logit of 'local' for the concatenated ``(s, a, s')`` rows of `x`."""
        return self.trunk(x)

    def loss(self, local: th.Tensor, other: th.Tensor) -> th.Tensor:
        """Cross-entropy (local: 1, global: 0) plus ``λ (‖∇D‖ − 1)²`` at random interpolations."""
        bce = F.binary_cross_entropy_with_logits(
            self.trunk(other), th.zeros(len(other), 1)
        ) + F.binary_cross_entropy_with_logits(self.trunk(local), th.ones(len(local), 1))
        mix = th.rand(len(local), 1)
        between = (mix * local + (1 - mix) * other).requires_grad_(True)
        out = self.trunk(between)
        (grad,) = th.autograd.grad(out, between, th.ones_like(out), create_graph=True)
        return bce + self.penalty * (grad.norm(2, dim=1) - 1).pow(2).mean()

    def update(self, local: th.Tensor, other: th.Tensor) -> float:
        """One Adam step on `loss`; returns it."""
        loss = self.loss(local, other)
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        return float(loss.item())

    @th.no_grad()
    def logit(self, x: th.Tensor) -> th.Tensor:
        """``log σ(D) − log(1 − σ(D))``, i.e. D's logit: the reward correction's input."""
        return self.trunk(x)


class OMPOReplayBuffer(ReplayBuffer):
    """SB3's replay buffer that also keeps every episode's first observation (OMPO's s₀ buffer)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.initial: list[np.ndarray] = []
        """First observations of the episodes (unnormalized), oldest first, at most buffer_size."""
        self._starts = np.ones(self.n_envs, dtype=bool)

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Unpickle for a resumed run, whose views start fresh episodes.

        The next transition of every env is then an episode's first (its state an s₀).
        """
        self.__dict__.update(state)
        self._starts = np.ones(self.n_envs, dtype=bool)

    def add(self, obs: Any, next_obs: Any, action: Any, reward: Any, done: Any, infos: Any) -> None:
        """Store a transition; an episode's first one also stores its observation as an s₀."""
        for i in np.nonzero(self._starts)[0]:
            self.initial.append(np.array(obs[i], copy=True))
        if len(self.initial) > self.buffer_size:
            del self.initial[: len(self.initial) - self.buffer_size]
        self._starts = np.asarray(done, dtype=bool).reshape(self.n_envs).copy()
        super().add(obs, next_obs, action, reward, done, infos)

    def recent(self, count: int) -> np.ndarray:
        """Row indices of the latest `count` additions (of every env), newest last."""
        count = min(count, filled(self))
        return (self.pos - count + np.arange(count)) % self.buffer_size

    def rows(self, idx: np.ndarray, env: Any = None) -> Any:
        """The transitions at row indices `idx` (a random env each), normalized like `sample`."""
        return self._get_samples(idx, env=env)

    def sample_initial(self, count: int, env: Any = None) -> np.ndarray:
        """`count` first observations drawn with replacement (normalized like the replay)."""
        # SB3's buffers draw from the global generator SB3 seeds; so do OMPO's draws
        picks = np.random.randint(0, len(self.initial), size=count)  # noqa: NPY002
        obs = np.stack([self.initial[i] for i in picks]).astype(np.float32)
        return obs if env is None else env.normalize_obs(obs).astype(np.float32)


class OMPO(SAC):
    """SB3's SAC trained by OMPO's losses (see the module docstring for the formulas).

    Args beyond SAC's (defaults: the Robust Gymnasium paper's OMPO table):
        local_size: transitions between discriminator trainings, and the local set's size.
        disc_rounds: global draws per training; disc_updates: updates per draw.
        disc_batch: discriminator minibatch (each of local and global).
        disc_hidden, disc_lr, grad_penalty: the discriminator's width, Adam rate and λ.
        exponent: ``p`` of the critic's power loss (> 1).
        tomac_alpha: weight of the reward correction and of the initial-state term.
        correction_weight: weight of the reward correction alone (None: `tomac_alpha`).
        reward_max: shift added to the reward before the clamp at 1e-6.
        critic_mix: share of the online critic in the target (OMPO: 0.05).
    """

    def __init__(
        self,
        policy: Any,
        env: Any,
        *,
        local_size: int = 1000,
        disc_rounds: int = 10,
        disc_updates: int = 20,
        disc_batch: int = 256,
        disc_hidden: int = 256,
        disc_lr: float = 3e-4,
        grad_penalty: float = 10.0,
        exponent: float = 1.5,
        tomac_alpha: float = 1e-3,
        correction_weight: float | None = None,
        reward_max: float = 1.0,
        critic_mix: float = 0.05,
        _init_setup_model: bool = True,
        **kwargs: Any,
    ) -> None:
        if not exponent > 1:
            raise ValueError(f"OMPO's exponent must be > 1, got {exponent!r}.")
        self.local_size, self.disc_rounds, self.disc_updates = local_size, disc_rounds, disc_updates
        self.disc_batch, self.disc_hidden, self.disc_lr = disc_batch, disc_hidden, disc_lr
        self.grad_penalty, self.exponent, self.tomac_alpha = grad_penalty, exponent, tomac_alpha
        self.reward_max, self.critic_mix = reward_max, critic_mix
        self.correction_weight = correction_weight
        self.sizes: list[tuple[th.Tensor, th.Tensor]] = []
        """Mean ``|logit|`` and shifted reward of each batch `shaped_reward` saw; `train` logs."""
        self.since_discriminator = 0
        """Transitions added since the discriminator last trained."""
        self.counts = {"critic": 0, "actor": 0, "target": 0, "discriminator": 0}
        """Updates done so far, by network (the schedule the tests count)."""
        kwargs.setdefault("replay_buffer_class", OMPOReplayBuffer)
        if policy == "MlpPolicy":
            policy = OMPOPolicy
        super().__init__(policy, env, _init_setup_model=False, **kwargs)
        if _init_setup_model:
            self._setup_model()

    def _setup_model(self) -> None:
        super()._setup_model()
        obs = int(np.prod(self.observation_space.shape))  # type: ignore[arg-type]
        act = int(np.prod(self.action_space.shape))  # type: ignore[arg-type]
        self.discriminator = TransitionDiscriminator(
            2 * obs + act, self.disc_hidden, self.disc_lr, self.grad_penalty
        )

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts, tensors = super()._get_torch_save_params()
        return [*state_dicts, "discriminator", "discriminator.optimizer"], tensors

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "discriminator", "sizes"]

    def _store_transition(self, replay_buffer: Any, *args: Any, **kwargs: Any) -> None:
        super()._store_transition(replay_buffer, *args, **kwargs)
        self.since_discriminator += self.n_envs

    # -- the updates ------------------------------------------------------------------------

    @staticmethod
    def _sas(data: Any) -> th.Tensor:
        parts = (data.observations, data.actions, data.next_observations)
        return th.cat([x.float() for x in parts], dim=1)

    def train_discriminator(self) -> list[float]:
        """OMPO's discriminator schedule on the latest `local_size` transitions vs the replay."""
        buf = self.replay_buffer
        assert isinstance(buf, OMPOReplayBuffer)
        env = self._vec_normalize_env
        local = buf.recent(max(1, self.local_size // self.n_envs))
        upper = filled(buf)
        losses = []
        for _ in range(self.disc_rounds):
            draw = np.random.choice(  # noqa: NPY002
                upper, size=min(self.local_size, upper), replace=False
            )
            for _ in range(self.disc_updates):
                mine = np.random.choice(  # noqa: NPY002
                    local, size=min(self.disc_batch, len(local)), replace=False
                )
                theirs = np.random.choice(  # noqa: NPY002
                    draw, size=min(self.disc_batch, len(draw)), replace=False
                )
                losses.append(
                    self.discriminator.update(
                        self._sas(buf.rows(mine, env)), self._sas(buf.rows(theirs, env))
                    )
                )
                self.counts["discriminator"] += 1
        self.since_discriminator = 0
        return losses

    @property
    def weight(self) -> float:
        """The reward correction's weight: `correction_weight`, or `tomac_alpha` when None."""
        w = self.correction_weight  # (None in models saved before it existed: __init__ sets it)
        return self.tomac_alpha if w is None else float(w)

    def shaped_reward(self, data: Any) -> th.Tensor:
        """``max(r + reward_max, 1e-6) − weight · logit D(s, a, s')`` for a batch."""
        reward = th.clamp(data.rewards + self.reward_max, min=1e-6)
        logit = self.discriminator.logit(self._sas(data))
        self.sizes.append((logit.abs().mean(), reward.abs().mean()))
        return reward - self.weight * logit

    def policy_moves(self, data: Any, init_obs: th.Tensor) -> tuple[th.Tensor, ...]:
        """``a' ~ π(s')``, ``log π(a'|s')`` and ``a₀ ~ π(s₀)``, drawn in one forward pass."""
        n = len(data.next_observations)
        both = th.cat([data.next_observations.float(), init_obs.float()])
        actions, log_prob = self.actor.action_log_prob(both)
        return actions[:n], log_prob[:n].reshape(-1, 1), actions[n:]

    def targets(
        self, data: Any, reward: th.Tensor, alpha: th.Tensor, moves: tuple, online: Any
    ) -> list[th.Tensor]:
        """``y_k`` per critic from the policy's `moves` and the online critics at ``(s', a')``."""
        next_actions, next_log_prob = moves[0], moves[1]
        targ = th.cat(self.critic_target(data.next_observations, next_actions), dim=1)
        low = th.min(targ, dim=1, keepdim=True)[0]
        mix = self.critic_mix
        return [
            reward
            + (1 - data.dones) * self.gamma * (mix * q + (1 - mix) * low - alpha * next_log_prob)
            for q in online
        ]

    def critic_loss(self, data: Any, init_obs: th.Tensor, alpha: th.Tensor) -> th.Tensor:
        """OMPO's critic loss (power loss plus the initial-state term), summed over the critics."""
        n = len(data.observations)
        with th.no_grad():
            reward = self.shaped_reward(data)
            moves = self.policy_moves(data, init_obs)
            online = self.critic(data.next_observations, moves[0])
            ys = self.targets(data, reward, alpha, moves, online)
        both = self.critic(
            th.cat([data.observations.float(), init_obs.float()]),
            th.cat([data.actions.float(), moves[2]]),
        )
        weight = (1 - self.gamma) * self.tomac_alpha
        power = self.exponent
        total = th.zeros(())
        for y, q in zip(ys, both, strict=True):
            total = total + (th.abs(y - q[:n]).pow(power) / power).mean() + weight * q[n:].mean()
        return total

    def actor_loss(self, data: Any, init_obs: th.Tensor, alpha: th.Tensor) -> th.Tensor:
        """OMPO's actor loss (see the module docstring)."""
        n = len(data.observations)
        reward = self.shaped_reward(data)
        moves = self.policy_moves(data, init_obs)
        both = self.critic(
            th.cat([data.next_observations.float(), init_obs.float()]),
            th.cat([moves[0], moves[2]]),
        )
        ys = self.targets(data, reward, alpha, moves, [q[:n] for q in both])
        with th.no_grad():
            qs = self.critic(data.observations, data.actions)
        weight = (1 - self.gamma) * self.tomac_alpha
        total = th.zeros(())
        for y, q, q_both in zip(ys, qs, both, strict=True):
            resid = y - q
            grad = th.clamp(resid, 0.0, 1e6).pow(self.exponent - 1).detach()
            total = total - (grad * resid).mean() - weight * q_both[n:].mean()
        return total / len(ys)

    def _alpha(self) -> th.Tensor:
        if self.log_ent_coef is not None:
            return th.exp(self.log_ent_coef.detach())
        return self.ent_coef_tensor

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        """`gradient_steps` OMPO updates (the discriminator first, when `local_size` have come)."""
        self.policy.set_training_mode(True)
        optimizers = [self.actor.optimizer, self.critic.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers.append(self.ent_coef_optimizer)
        self._update_learning_rate(optimizers)
        buf = self.replay_buffer
        assert isinstance(buf, OMPOReplayBuffer)
        env = self._vec_normalize_env
        if self.since_discriminator >= self.local_size:
            losses = self.train_discriminator()
            self.logger.record("train/discriminator_loss", float(np.mean(losses)))
        critic_losses, actor_losses = [], []
        for _ in range(gradient_steps):
            data = buf.sample(batch_size, env=env)
            init_obs = th.as_tensor(buf.sample_initial(batch_size, env), device=self.device)
            loss = self.critic_loss(data, init_obs, self._alpha())
            self.critic.optimizer.zero_grad()
            loss.backward()
            self.critic.optimizer.step()
            critic_losses.append(loss.item())
            self.counts["critic"] += 1
            if self._n_updates % self.target_update_interval == 0:
                actor_losses.append(self._actor_step(data, init_obs))
            self._n_updates += 1
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/critic_loss", float(np.mean(critic_losses)))
        if actor_losses:
            self.logger.record("train/actor_loss", float(np.mean(actor_losses)))
        self.logger.record("train/ent_coef", float(self._alpha().item()))
        self._record_correction()

    def _record_correction(self) -> None:
        """Log the mean correction size of this call's critic batches, and its share."""
        if not self.sizes:  # no update in this call
            return
        logit, reward = (float(th.stack(x).mean()) for x in zip(*self.sizes, strict=True))
        self.sizes = []
        self.logger.record("train/logit_abs", logit)
        self.logger.record("train/correction_abs", self.weight * logit)
        self.logger.record("train/correction_ratio", self.weight * logit / max(reward, 1e-12))

    def _actor_step(self, data: Any, init_obs: th.Tensor) -> float:
        """The actor, then the temperature, then the soft target update (OMPO's order)."""
        critics = [*self.critic.parameters(), *self.critic_target.parameters()]
        for p in critics:  # the actor's gradient only: no weight gradients for the critics
            p.requires_grad_(False)
        try:
            loss = self.actor_loss(data, init_obs, self._alpha())
            self.actor.optimizer.zero_grad()
            loss.backward()
        finally:
            for p in critics:
                p.requires_grad_(True)
        self.actor.optimizer.step()
        self.counts["actor"] += 1
        if self.ent_coef_optimizer is not None and self.log_ent_coef is not None:
            _, log_prob = self.actor.action_log_prob(data.observations)
            assert isinstance(self.target_entropy, float)
            ent_loss = -(self.log_ent_coef * (log_prob + self.target_entropy).detach()).mean()
            self.ent_coef_optimizer.zero_grad()
            ent_loss.backward()
            self.ent_coef_optimizer.step()
        polyak_update(self.critic.parameters(), self.critic_target.parameters(), self.tau)
        polyak_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)
        self.counts["target"] += 1
        return float(loss.item())
