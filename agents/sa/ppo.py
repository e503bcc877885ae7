"""SA-PPO: PPO with the state-adversarial regulariser of Zhang et al. 2020 (NeurIPS).

The policy is asked to act alike on every observation in a small ball around each state it
was trained on: each minibatch update adds::

    κ · mean_s max_{ŝ ∈ B_ε(s)} KL(π(·|s) ‖ π(·|ŝ))

to PPO's loss. The inner maximisation runs projected signed-gradient steps (PGD, from a
uniform random start in the ball) for the whole minibatch at once: one forward and backward
pass per step over ``[batch, obs]``, with ``π(·|s)`` held fixed; the regulariser is then
differentiated with respect to the policy's parameters at the ``ŝ`` found. The ball is L∞ and
lives in the units the budget is given in: ``"normalized"`` (ATLA's budgets: the policy's input
behind `VecNormalize`, so ε applies to it directly) or ``"raw"`` (ε divided by the normalizer's
std per dimension), the same conventions as `advgame.ObservationDisruptor`. ε grows linearly
from 0 to its full value over the first ``sa_ramp`` of the run's steps, as in SA-PPO.

`SAPPO` is an SB3 `PPO` whose update (``train``) is written here with that extra term; it
saves and loads as a PPO (a released SA-PPO agent plays as a plain PPO checkpoint).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.utils import explained_variance
from torch.nn import functional as F

from advgame.core.numpy_net import NumpyNet, sb3_modules

__all__ = ["SAPPO", "SASettings", "kl_rows", "pgd_start", "pgd_step", "sa_regulariser"]


def kl_rows(reference: Any, dist: Any) -> torch.Tensor:
    """``KL(reference ‖ dist)`` per row (a Gaussian: summed over action dimensions)."""
    kl = torch.distributions.kl_divergence(reference, dist)
    return kl.sum(-1) if kl.dim() > 1 else kl


def _kl(policy: Any, obs: torch.Tensor, reference: Any) -> torch.Tensor:
    """``KL(reference ‖ π(·|obs))`` per row."""
    return kl_rows(reference, policy.get_distribution(obs).distribution)


def pgd_start(
    obs: torch.Tensor, eps: torch.Tensor, steps: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(step size, δ₀)`` of a PGD walk of `steps` steps in the L∞ ball of radius `eps`.

    The walk can cross the ball 2.5 times (Madry et al.); it starts at a uniform random point.
    """
    step = 2.5 * eps / max(steps, 1)
    return step, (torch.rand_like(obs) * 2 - 1) * eps


def pgd_step(
    delta: torch.Tensor, grad: torch.Tensor, step: torch.Tensor, eps: torch.Tensor
) -> torch.Tensor:
    """One signed ascent step on `delta`, projected back onto the L∞ ball of radius `eps`."""
    return torch.max(torch.min(delta + step * grad.sign(), eps), -eps)


def sa_regulariser(
    policy: Any,
    obs: torch.Tensor,
    eps: torch.Tensor,
    steps: int,
    low: float = -np.inf,
    high: float = np.inf,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(mean KL at the ŝ found, ŝ)``: the SA regulariser of a minibatch, differentiable in θ.

    Args:
        policy: an SB3 actor-critic policy (``get_distribution``).
        obs: the minibatch of policy inputs ``[batch, obs]``.
        eps: the L∞ radius per input dimension (a tensor broadcastable to `obs`).
        steps: PGD steps; 0 keeps the random start.
        low: the lower end of the range inputs are clipped to (VecNormalize's ``-clip_obs``).
        high: its upper end (``clip_obs``).

    """
    with torch.no_grad():
        clean = policy.get_distribution(obs).distribution
        reference = type(clean)(clean.mean.detach(), clean.stddev.detach())
    if not torch.any(eps > 0):
        return torch.zeros((), dtype=obs.dtype), obs
    step, delta = pgd_start(obs, eps, steps)
    walked = _numpy_walk(policy, obs, eps, step, steps, (low, high), delta)
    if walked is not None:
        delta = walked
    for _ in range(0 if walked is not None else steps):
        delta.requires_grad_(True)
        x = torch.clamp(obs + delta, low, high)
        (grad,) = torch.autograd.grad(_kl(policy, x, reference).sum(), delta)
        delta = pgd_step(delta.detach(), grad, step, eps)
    attacked = torch.clamp(obs + delta.detach(), low, high)
    return _kl(policy, attacked, reference).mean(), attacked


def _numpy_walk(
    policy: Any,
    obs: torch.Tensor,
    eps: torch.Tensor,
    step: torch.Tensor,
    steps: int,
    bounds: tuple[float, float],
    delta: torch.Tensor,
) -> torch.Tensor | None:
    """`sa_regulariser`'s PGD from `delta`, through a NumPy copy of the actor's Gaussian mean.

    The same walk as the torch loop (signed steps on ``KL = Σ (μ(ŝ) − μ(s))² / 2σ²``, the
    clip's gradient, the projection), without a graph and an autograd pass per step; the
    copy is made for this minibatch (the weights change after every one). None where the
    policy is not a plain Gaussian MLP (`advgame.core.numpy_net.sb3_modules`): torch walks.
    """
    modules = sb3_modules(policy, "mean")
    net = None if modules is None else NumpyNet.of(modules, probe=False)
    if net is None or steps < 1:
        return None
    low, high = np.float32(bounds[0]), np.float32(bounds[1])
    inv_var = torch.exp(-2 * policy.log_std.detach()).numpy()  # 1 / σ² per action dimension
    x0, e, h = obs.detach().numpy(), eps.numpy(), step.numpy()
    d = delta.numpy()
    reference = net.forward(x0)[0]
    for _ in range(steps):
        pre = x0 + d
        mean, tape = net.forward(pre.clip(low, high))
        grad = net.backward(tape, (mean - reference) * inv_var) * ((pre >= low) & (pre <= high))
        d = np.maximum(np.minimum(d + h * np.sign(grad), e), -e)
    return torch.as_tensor(d)


class SASettings:
    """The SA learners' shared settings: ε now (ramped) and the inputs' clip range.

    A mixin for an SB3 algorithm (`SAPPO`, `advgame.agents.sa.recurrent.SARecurrentPPO`): its
    ``__init__`` takes the ``sa_*`` keywords (defaults: the class's `sa_defaults`), stores them
    as attributes and passes everything else on to the algorithm.
    """

    sa_defaults: ClassVar[dict[str, Any]] = {
        "sa_kappa": 0.1, "sa_eps": 0.075, "sa_steps": 10, "sa_ramp": 0.75,
        "sa_space": "normalized", "sa_total_steps": 1,
    }  # fmt: skip
    """The ``sa_*`` keywords' defaults (SA-PPO's Hopper configs)."""
    sa_kappa: float
    sa_steps: int
    sa_eps: float
    sa_ramp: float
    sa_space: str
    sa_total_steps: int
    num_timesteps: int
    observation_space: Any
    get_vec_normalize_env: Any

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        for name, default in self.sa_defaults.items():
            setattr(self, name, kwargs.pop(name, default))
        super().__init__(*args, **kwargs)

    def sa_radius(self) -> torch.Tensor:
        """ε now (ramped), per policy-input dimension."""
        frac = self.num_timesteps / max(self.sa_total_steps * self.sa_ramp, 1)
        eps = self.sa_eps * min(1.0, frac) if self.sa_ramp > 0 else self.sa_eps
        size = int(np.prod(self.observation_space.shape or ()))
        radius = np.full(size, eps, dtype=np.float32)
        rms = getattr(self.get_vec_normalize_env(), "obs_rms", None)
        if self.sa_space == "raw" and rms is not None:
            radius = radius / np.sqrt(rms.var + 1e-8).astype(np.float32)
        return torch.as_tensor(radius)

    def _clip_range(self) -> float:
        """VecNormalize's ``clip_obs`` (inputs lie in ``[-clip, clip]``), inf without one."""
        norm = self.get_vec_normalize_env()
        return float(norm.clip_obs) if norm is not None else np.inf


class SAPPO(SASettings, PPO):
    """SB3 PPO plus the state-adversarial regulariser (see the module doc).

    Args:
        sa_kappa: κ, the regulariser's weight (SA-PPO/ATLA configs: 0.1).
        sa_eps: ε, the full L∞ radius, in `sa_space` units.
        sa_steps: PGD steps of the inner maximisation (SA-PPO: 10).
        sa_ramp: fraction of `sa_total_steps` over which ε grows from 0 (SA-PPO: 0.75).
        sa_space: ``"normalized"`` or ``"raw"`` (see the module doc).
        sa_total_steps: the run's planned steps (for the ramp).
        *args: SB3 `PPO`'s positional arguments.
        **kwargs: SB3 `PPO`'s keyword arguments.

    """

    def train(self) -> None:
        """One PPO update over the rollout buffer, with the SA regulariser on each minibatch."""
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        clip = self.clip_range(self._current_progress_remaining)  # type: ignore[operator]
        radius, bound = self.sa_radius(), self._clip_range()
        logs: dict[str, list[float]] = {
            k: [] for k in ("pg", "value", "entropy", "sa", "kl", "clip")
        }
        for _epoch in range(self.n_epochs):
            for batch in self.rollout_buffer.get(self.batch_size):
                actions = batch.actions
                if isinstance(self.action_space, spaces.Discrete):
                    actions = actions.long().flatten()
                values, log_prob, entropy = self.policy.evaluate_actions(
                    batch.observations, actions
                )
                adv = batch.advantages
                if self.normalize_advantage and len(adv) > 1:
                    adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                ratio = torch.exp(log_prob - batch.old_log_prob)
                surrogate = torch.min(adv * ratio, adv * torch.clamp(ratio, 1 - clip, 1 + clip))
                pg_loss = -surrogate.mean()
                value_loss = F.mse_loss(batch.returns, values.flatten())
                entropy_loss = -torch.mean(entropy if entropy is not None else -log_prob)
                sa, _ = sa_regulariser(
                    self.policy, batch.observations, radius, self.sa_steps, -bound, bound
                )
                loss = pg_loss + self.ent_coef * entropy_loss + self.vf_coef * value_loss
                loss = loss + self.sa_kappa * sa
                self.policy.optimizer.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
                self.policy.optimizer.step()
                with torch.no_grad():
                    log_ratio = log_prob - batch.old_log_prob
                    logs["kl"].append(float(torch.mean((torch.exp(log_ratio) - 1) - log_ratio)))
                    logs["clip"].append(float(torch.mean((torch.abs(ratio - 1) > clip).float())))
                for key, value in (
                    ("pg", pg_loss),
                    ("value", value_loss),
                    ("entropy", entropy_loss),
                    ("sa", sa),
                ):
                    logs[key].append(float(value.detach()))
            self._n_updates += 1
        explained = explained_variance(
            self.rollout_buffer.values.flatten(), self.rollout_buffer.returns.flatten()
        )
        for key, name in (("pg", "policy_gradient_loss"), ("value", "value_loss"),
                          ("entropy", "entropy_loss"), ("sa", "sa_regulariser"),
                          ("kl", "approx_kl"), ("clip", "clip_fraction")):  # fmt: skip
            self.logger.record(f"train/{name}", float(np.mean(logs[key])))
        self.logger.record("train/sa_eps", float(radius.max()))
        self.logger.record("train/explained_variance", float(explained))
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
