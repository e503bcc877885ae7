"""ATLA-LSTM-SA's learner: sb3-contrib's RecurrentPPO with the state-adversarial regulariser.

Zhang et al. 2021 (ICLR, "Robust RL on state observations with learned optimal adversary",
ATLA) train their most robust agents, ATLA-LSTM-SA, as an LSTM policy with SA-PPO's
regulariser (`advgame.agents.sa.ppo`); the authors' code is ``huanzhang12/ATLA_robust_RL``,
``src/policy_gradients/steps.py``, ``get_state_kl_bound_sgld`` and ``robust_ppo_step``.
With memory, the ball is around a whole observation *sequence*: one δ per step and feature,
and a perturbation at step t moves the actions at t and at every later step through the
LSTM state. `SARecurrentPPO` adds, to every minibatch update of sb3-contrib's
``RecurrentPPO``::

    κ · max_{‖δ_t‖∞ ≤ ε ∀t} mean_t KL(π(·|s_{≤t}) ‖ π(·|s_{≤t} + δ_{≤t}))

over the minibatch's sequences, each unrolled from the LSTM state stored at its first step
(zeroed where the sequence starts an episode), padded steps masked out. The inner maximisation
is `advgame.agents.sa.ppo.sa_regulariser`'s PGD on the whole ``[sequences × steps, obs]``
perturbation at once: a uniform random start in the ball, signed steps of 2.5 ε / steps,
projection onto the ball, inputs clipped to VecNormalize's range. ε is ramped and measured as
in SA-PPO (`advgame.agents.sa.ppo.SASettings`). It saves as a RecurrentPPO: a released agent
plays as ``algo="recurrent-ppo"`` and ``RecurrentPPO.load`` reads its files (the ``sa_*``
attributes ride along, unused).

Deviations from the authors' code, and why:

* **Minibatches of sequences from the rollout's stored states**, not ATLA's full-batch update
  (10 epochs of one Adam step over the 2,048 steps, each episode unrolled from a zero state
  with the current parameters): the regulariser follows RecurrentPPO's own update, so the
  clean and perturbed unrolls start from the state the rollout stored at the sequence start
  (what the PPO loss uses too), and perturbations carry forward within the sequence only.
* **KL with its 1/2**: the term is ``KL = Σ_j (μ̃_j − μ_j)² / 2σ_j²`` (plus the std terms,
  zero here) as in `advgame.agents.SAPPOConfig`, so κ means the same in both; ATLA's term is
  ``Σ_j ((μ̃_j − μ_j)/σ_j)²``, twice ours: ATLA's κ = 0.3 is κ = 0.6 here.
* **PGD, not SGLD**: no noise on the sign (ATLA's is ``sqrt(2·step·1e-5)/(i+2)``, vanishing),
  a uniform start instead of ``sign(randn)·ε/steps``, and steps of 2.5 ε / steps instead of
  ε / steps, as SA-PPO here; the perturbed inputs are also clipped to the normalizer's range
  (ATLA does not clip), so ŝ is an input the policy can really be given.
* **Means only over valid steps**: the KL averages over the minibatch's real steps (the mask);
  ATLA averages over the whole batch of 2,048 steps, which is the same where nothing is padded.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.utils import explained_variance

from advgame.agents.recurrent.ppo import UnrolledRecurrentPPO, unrolled
from advgame.agents.sa.ppo import SASettings, kl_rows, pgd_start, pgd_step

__all__ = ["SARecurrentPPO", "recurrent_sa_regulariser"]

States = tuple[torch.Tensor, torch.Tensor]


def _masked_kl(
    policy: Any, x: torch.Tensor, states: States, starts: torch.Tensor, ref: Any, w: torch.Tensor
) -> torch.Tensor:
    """``Σ_t w_t KL(ref_t ‖ π(·|x_{≤t}))``: the sequences of `x` unrolled from `states`."""
    dist, _ = policy.get_distribution(x, states, starts)
    return (kl_rows(ref, dist.distribution) * w).sum()


def recurrent_sa_regulariser(
    policy: Any,
    obs: torch.Tensor,
    states: States,
    starts: torch.Tensor,
    mask: torch.Tensor,
    eps: torch.Tensor,
    steps: int,
    low: float = -np.inf,
    high: float = np.inf,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(mean KL over valid steps at the ŝ found, ŝ)``, differentiable in the parameters.

    Args:
        policy: an sb3-contrib recurrent actor-critic policy (``get_distribution``).
        obs: the padded sequences, flattened ``[n_seq * max_len, obs]`` (RecurrentPPO's
            minibatch layout).
        states: the actor LSTM's ``(h, c)`` at each sequence's first step,
            ``[layers, n_seq, hidden]``.
        starts: episode starts per row of `obs` (the LSTM state is zeroed there).
        mask: which rows are real steps (padding: False); padded rows count nothing and
            are not perturbed.
        eps: the L∞ radius per input dimension (a tensor broadcastable to `obs`).
        steps: PGD steps; 0 keeps the random start.
        low: the lower end of the range inputs are clipped to (VecNormalize's ``-clip_obs``).
        high: its upper end (``clip_obs``).

    """
    states, starts = unrolled(states, starts)
    w = mask.reshape(-1).to(obs.dtype)
    with torch.no_grad():
        clean = policy.get_distribution(obs, states, starts)[0].distribution
        ref = type(clean)(clean.mean.detach(), clean.stddev.detach())
    if not torch.any(eps > 0):
        return torch.zeros((), dtype=obs.dtype), obs
    step, delta = pgd_start(obs, eps, steps)
    delta = delta * w[:, None]
    for _ in range(steps):
        delta.requires_grad_(True)
        x = torch.clamp(obs + delta, low, high)
        (grad,) = torch.autograd.grad(_masked_kl(policy, x, states, starts, ref, w), delta)
        delta = pgd_step(delta.detach(), grad, step, eps)
    attacked = torch.clamp(obs + delta.detach(), low, high)
    total = _masked_kl(policy, attacked, states, starts, ref, w)
    return total / w.sum().clamp(min=1.0), attacked


class SARecurrentPPO(SASettings, UnrolledRecurrentPPO):
    """sb3-contrib ``RecurrentPPO`` plus the sequence SA regulariser (see the module doc).

    Args:
        sa_kappa: κ, the regulariser's weight (ATLA-LSTM-SA configs: 0.3, see the module doc
            on the factor 2).
        sa_eps: ε, the full L∞ radius, in `sa_space` units (ATLA: Hopper 0.075, Walker2d 0.05).
        sa_steps: PGD steps of the inner maximisation (ATLA-LSTM-SA: 2).
        sa_ramp: fraction of `sa_total_steps` over which ε grows from 0 (ATLA: 0.75).
        sa_space: ``"normalized"`` or ``"raw"`` (as `advgame.agents.sa.ppo.SAPPO`).
        sa_total_steps: the run's planned steps (for the ramp).
        *args: ``RecurrentPPO``'s positional arguments.
        **kwargs: ``RecurrentPPO``'s keyword arguments.

    """

    sa_defaults: ClassVar[dict[str, Any]] = {
        **SASettings.sa_defaults, "sa_kappa": 0.3, "sa_steps": 2,
    }  # fmt: skip
    """ATLA-LSTM-SA's: κ 0.3 and 2 steps; ε, ramp and units as SA-PPO's."""

    def _ppo_loss(
        self, batch: Any, clip: float, clip_vf: float | None, logs: dict[str, list[float]]
    ) -> tuple[torch.Tensor, float]:
        """RecurrentPPO's minibatch loss (clipped surrogate, value, entropy) and approx KL."""
        actions = batch.actions
        if isinstance(self.action_space, spaces.Discrete):
            actions = batch.actions.long().flatten()
        mask = batch.mask > 1e-8
        policy: Any = self.policy  # a RecurrentActorCriticPolicy (SB3 types it feed-forward)
        values, log_prob, entropy = policy.evaluate_actions(
            batch.observations, actions, batch.lstm_states, batch.episode_starts
        )
        values = values.flatten()
        adv = batch.advantages
        if self.normalize_advantage:
            adv = (adv - adv[mask].mean()) / (adv[mask].std() + 1e-8)
        ratio = torch.exp(log_prob - batch.old_log_prob)
        surrogate = torch.min(adv * ratio, adv * torch.clamp(ratio, 1 - clip, 1 + clip))
        pg_loss = -torch.mean(surrogate[mask])
        logs["clip"].append(torch.mean((torch.abs(ratio - 1) > clip).float()[mask]).item())
        if clip_vf is not None:
            values = batch.old_values + torch.clamp(values - batch.old_values, -clip_vf, clip_vf)
        value_loss = torch.mean(((batch.returns - values) ** 2)[mask])
        entropy_loss = -torch.mean((-log_prob if entropy is None else entropy)[mask])
        for key, value in (("pg", pg_loss), ("value", value_loss), ("entropy", entropy_loss)):
            logs[key].append(value.item())
        loss = pg_loss + self.ent_coef * entropy_loss + self.vf_coef * value_loss
        with torch.no_grad():
            log_ratio = log_prob - batch.old_log_prob
            approx_kl = float(torch.mean(((torch.exp(log_ratio) - 1) - log_ratio)[mask]))
        return loss, approx_kl

    def _sa_term(self, batch: Any, radius: torch.Tensor, bound: float) -> torch.Tensor:
        """The minibatch's regulariser (zero, and not computed, at κ = 0)."""
        if self.sa_kappa == 0:
            return torch.zeros(())
        sa, _ = recurrent_sa_regulariser(
            self.policy, batch.observations, batch.lstm_states.pi, batch.episode_starts,
            batch.mask > 1e-8, radius, self.sa_steps, -bound, bound,
        )  # fmt: skip
        return sa

    def train(self) -> None:
        """One RecurrentPPO update over the rollout buffer, with κ · the regulariser added."""
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        progress = self._current_progress_remaining
        clip = self.clip_range(progress)
        vf_range: Any = self.clip_range_vf  # a schedule or None
        clip_vf = None if vf_range is None else vf_range(progress)
        radius, bound = self.sa_radius(), self._clip_range()
        logs: dict[str, list[float]] = {k: [] for k in ("pg", "value", "entropy", "sa", "clip")}
        approx_kls: list[float] = []
        loss = torch.zeros(())
        for _epoch in range(self.n_epochs):
            approx_kls = []
            stop = False
            for batch in self.rollout_buffer.get(self.batch_size):
                loss, approx_kl = self._ppo_loss(batch, clip, clip_vf, logs)
                approx_kls.append(approx_kl)
                if self.target_kl is not None and approx_kl > 1.5 * self.target_kl:
                    stop = True
                    break
                sa = self._sa_term(batch, radius, bound)
                logs["sa"].append(float(sa.detach()))
                if self.sa_kappa != 0:
                    loss = loss + self.sa_kappa * sa
                self.policy.optimizer.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
                self.policy.optimizer.step()
            self._n_updates += 1
            if stop:
                break
        self._record(logs, approx_kls, loss, clip, clip_vf, radius)

    def _record(
        self,
        logs: dict[str, list[float]],
        approx_kls: list[float],
        loss: torch.Tensor,
        clip: float,
        clip_vf: float | None,
        radius: torch.Tensor,
    ) -> None:
        """RecurrentPPO's ``train/*`` records, plus ``sa_regulariser`` and ``sa_eps``."""
        explained = explained_variance(
            self.rollout_buffer.values.flatten(), self.rollout_buffer.returns.flatten()
        )
        for key, name in (("entropy", "entropy_loss"), ("pg", "policy_gradient_loss"),
                          ("value", "value_loss"), ("clip", "clip_fraction"),
                          ("sa", "sa_regulariser")):  # fmt: skip
            values = logs[key]  # "sa" is empty where the first minibatch stopped early
            self.logger.record(f"train/{name}", float(np.mean(values)) if values else 0.0)
        self.logger.record("train/approx_kl", float(np.mean(approx_kls)))
        self.logger.record("train/loss", loss.item())
        self.logger.record("train/explained_variance", float(explained))
        if hasattr(self.policy, "log_std"):
            self.logger.record("train/std", torch.exp(self.policy.log_std).mean().item())
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/clip_range", clip)
        if clip_vf is not None:
            self.logger.record("train/clip_range_vf", clip_vf)
        self.logger.record("train/sa_eps", float(radius.max()))
