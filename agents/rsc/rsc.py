"""RSC (Ding et al., NeurIPS 2023): robust state-confounded SAC on Stable-Baselines3's SAC.

RSC trains SAC on a batch in which a share (`augmented_ratio`, the Robust Gymnasium table's
0.5) of the real transitions is replaced by *augmented* ones that break the spurious
correlations between parts of the state (the paper's empirical algorithm and its Eq. 7; the
authors publish no code, so this follows the paper's text; choices it leaves open: docs/causal.md):

1. **World model** (every update): one step of `advgame.agents.rsc.model.CausalWorldModel`,
   a structural causal model with a learnable binary causal graph over ``(s, a) -> (s', r)``,
   on a fresh batch of one-step replay transitions.
2. **Augmented transitions**: a batch of one-step transitions has its first
   ``round(augmented_ratio · batch_size)`` states perturbed by Eq. 7
   (`advgame.agents.rsc.model.perturb_states`: one dimension moved to the value of the batch
   row most different in it and most similar elsewhere); the world model, under its most
   probable graph, gives each perturbed ``(s̃, a)`` its next state and reward. They keep their
   action and done flag and are discounted by ``γ`` (one step).
3. **SAC** (SB3's losses, written out below as `critic_loss` and `actor_loss`): the rest of
   the batch are real transitions with SB3's n-step returns (`n_steps`, the table's 4:
   discount ``γ^k`` per row); temperature, critic, actor and soft target update as SB3's SAC.

Augmentation starts once the world model has had `model_warmup` updates (before that the batch
is all real). The critic has its own step size (`critic_learning_rate`, the table's 1e-3; the
actor and the temperature use `learning_rate`, 3e-4).
"""

from __future__ import annotations

import warnings
from collections import defaultdict
from typing import Any

import numpy as np
import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.type_aliases import ReplayBufferSamples
from stable_baselines3.common.utils import polyak_update, update_learning_rate
from torch.nn import functional as F

from advgame.agents.common.replay_store import filled
from advgame.agents.rsc.model import CausalWorldModel, perturb_states

__all__ = ["MODE_ERROR_EVERY", "RSC", "graph_logs", "one_step_samples"]

MODE_ERROR_EVERY = 100
"""World-model updates between two measurements of its error under the most probable graph
(``train/model_error_mode``: the graph the augmented rows are generated under) and of that
graph (`graph_logs`)."""


def one_step_samples(buffer: ReplayBuffer, count: int, env: Any = None) -> ReplayBufferSamples:
    """`count` plain one-step transitions from any SB3 replay buffer, n-step ones included."""
    # SB3's buffers draw from the global generator SB3 seeds; so does RSC
    idx = np.random.randint(0, filled(buffer), size=count)  # noqa: NPY002
    return ReplayBuffer._get_samples(buffer, idx, env=env)


def graph_logs(model: CausalWorldModel, errors: th.Tensor) -> list[tuple[str, float]]:
    """What the run's ``learning.csv`` records of the world model, as ``(name, value)``.

    ``model_error_mode``: the mean of `errors` (each output's standardised squared error under
    the most probable graph, the one augmentation uses); per output ``o`` (``s0``, ``s1``, ...,
    ``r``): ``model_error_mode/o``, ``graph_parents/o`` (the graph's inputs of that output with
    probability > 0.5, its own past included) and, for a state output, ``graph_self/o`` (the
    probability of its own ``s[i] → s'[i]`` edge: 1 when `keep_self_edges`). The whole graph's logits are in every checkpoint
    (``world_model.graph_logits``).
    """
    parents = model.mode_graph().sum(dim=1)
    probs = model.edge_probabilities().detach()
    rows: list[tuple[str, float]] = [("model_error_mode", float(errors.mean()))]
    for o in range(model.obs_dim + 1):
        name = f"s{o}" if o < model.obs_dim else "r"
        rows += [(f"model_error_mode/{name}", float(errors[o])),
                 (f"graph_parents/{name}", float(parents[o]))]  # fmt: skip
        if o < model.obs_dim:
            rows.append((f"graph_self/{name}", float(probs[o, o])))
    return rows


class RSC(SAC):
    """SB3's SAC trained on RSC's mix of real and augmented transitions (see the module docstring).

    Args beyond SAC's (defaults: the Robust Gymnasium paper's RSC table where it has a value):
        critic_learning_rate: the critic's Adam step size (the actor's: ``learning_rate``).
        augmented_ratio: share of each SAC batch that is augmented (rounded to whole rows).
        sigma: standard deviation of the Gaussian jitter on augmented states.
        bound: clip of that jitter, per dimension.
        vae_sigma: standard deviation of the world model's Gaussian likelihood.
        model_hidden: width of the world model's per-output hidden layers.
        model_lr: Adam step size of the world model's networks.
        graph_lr: Adam step size of its causal graph's logits.
        sparsity: λ, the weight of the graph's sparsity term (`CausalWorldModel.losses`).
        temperature: τ of the Gumbel-Softmax draws of the graph (``graph_draws="relaxed"``).
        model_warmup: world-model updates before the first augmented row.
        graph_draws: ``"hard"`` (Bernoulli draws, score-function gradient) or ``"relaxed"``.
        keep_self_edges: each state output's own past, ``s[i] → s'[i]``, is always an edge.
        clip_to_support: augmented next states and rewards clipped to the data's range.
    """

    def __init__(
        self,
        policy: Any,
        env: Any,
        *,
        critic_learning_rate: float = 1e-3,
        augmented_ratio: float = 0.5,
        sigma: float = 0.01,
        bound: float = 0.01,
        vae_sigma: float = 1.0,
        model_hidden: int = 64,
        model_lr: float = 1e-3,
        graph_lr: float = 3e-2,
        sparsity: float = 3e-3,
        temperature: float = 1.0,
        model_warmup: int = 1000,
        graph_draws: str = "hard",
        keep_self_edges: bool = True,
        clip_to_support: bool = False,
        _init_setup_model: bool = True,
        **kwargs: Any,
    ) -> None:
        if not 0 <= augmented_ratio <= 1:
            raise ValueError(f"RSC's augmented_ratio must be in [0, 1], got {augmented_ratio!r}.")
        self.critic_learning_rate, self.augmented_ratio = critic_learning_rate, augmented_ratio
        self.sigma, self.bound, self.vae_sigma = sigma, bound, vae_sigma
        self.model_hidden, self.model_lr, self.graph_lr = model_hidden, model_lr, graph_lr
        self.sparsity, self.temperature, self.model_warmup = sparsity, temperature, model_warmup
        self.graph_draws, self.keep_self_edges = graph_draws, keep_self_edges
        self.clip_to_support = clip_to_support
        self.counts = {"model": 0, "critic": 0, "actor": 0, "real_rows": 0, "augmented_rows": 0}
        """Updates (by network) and SAC batch rows (real, augmented) so far."""
        super().__init__(policy, env, _init_setup_model=False, **kwargs)
        if _init_setup_model:
            self._setup_model()

    def _setup_model(self) -> None:
        with warnings.catch_warnings():
            if "n_steps" in self.replay_buffer_kwargs:  # a loaded model's n-step buffer is set
                warnings.filterwarnings("ignore", message="`n_steps=", category=UserWarning)
            super()._setup_model()
        obs = int(np.prod(self.observation_space.shape))  # type: ignore[arg-type]
        act = int(np.prod(self.action_space.shape))  # type: ignore[arg-type]
        self.world_model = CausalWorldModel(
            obs, act, hidden=self.model_hidden, lr=self.model_lr, graph_lr=self.graph_lr,
            sparsity=self.sparsity, temperature=self.temperature, sigma=self.vae_sigma,
            graph_draws=self.graph_draws, keep_self_edges=self.keep_self_edges,
            clip_to_support=self.clip_to_support,
        )  # fmt: skip

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts, tensors = super()._get_torch_save_params()
        return [*state_dicts, "world_model", "world_model.optimizer"], tensors

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "world_model"]

    # -- the data ---------------------------------------------------------------------------

    def augmented_rows(self, batch_size: int) -> int:
        """Rows of a SAC batch that are augmented (none before `model_warmup` model updates)."""
        if self.counts["model"] < self.model_warmup:
            return 0
        return round(self.augmented_ratio * batch_size)

    def update_world_model(
        self, batch_size: int, logs: dict[str, list[float]] | None = None
    ) -> float:
        """One world-model update on `batch_size` one-step replay transitions; returns its loss.

        Every `MODE_ERROR_EVERY` updates the same batch also measures, into `logs`, the error
        under the most probable graph (no extra draw from the replay) and that graph:
        `graph_logs`.
        """
        data = one_step_samples(self.replay_buffer, batch_size, self._vec_normalize_env)  # type: ignore[arg-type]
        batch = (data.observations, data.actions, data.next_observations, data.rewards)
        loss = self.world_model.update(*batch)
        self.counts["model"] += 1
        if logs is not None and self.counts["model"] % MODE_ERROR_EVERY == 0:
            for name, value in graph_logs(self.world_model, self.world_model.mode_errors(*batch)):
                logs[name].append(value)
        return loss

    def augment(self, data: ReplayBufferSamples, rows: int) -> ReplayBufferSamples:
        """The first `rows` transitions of `data`, states perturbed (Eq. 7), outcomes predicted."""
        states, _ = perturb_states(data.observations, rows, self.sigma, self.bound)
        actions = data.actions[:rows]
        next_obs, rewards = self.world_model.predict(states, actions)
        discounts = th.full((rows, 1), self.gamma, device=states.device)
        return ReplayBufferSamples(states, actions, next_obs, data.dones[:rows], rewards, discounts)

    def mixed_batch(self, batch_size: int) -> ReplayBufferSamples:
        """A SAC batch: augmented rows first, then real (n-step) ones; discounts per row."""
        env = self._vec_normalize_env
        rows = self.augmented_rows(batch_size)
        real = self.replay_buffer.sample(batch_size - rows, env=env)  # type: ignore[union-attr]
        if real.discounts is None:
            real = real._replace(discounts=th.full_like(real.rewards, self.gamma))
        self.counts["real_rows"] += batch_size - rows
        if rows == 0:
            return real
        pool = one_step_samples(self.replay_buffer, batch_size, env)  # type: ignore[arg-type]
        fake = self.augment(pool, rows)
        self.counts["augmented_rows"] += rows
        if rows == batch_size:
            return fake
        parts = zip(fake, real, strict=True)
        return ReplayBufferSamples(*(th.cat([a, b]).float() for a, b in parts))  # type: ignore[list-item]

    # -- SAC's losses -------------------------------------------------------------------------

    def critic_loss(self, data: ReplayBufferSamples, ent_coef: th.Tensor) -> th.Tensor:
        """SB3's twin-critic loss with per-row discounts: ``½ Σ_k mean((Q_k(s, a) − y)²)``."""
        with th.no_grad():
            next_actions, next_log_prob = self.actor.action_log_prob(data.next_observations)
            next_q = th.cat(self.critic_target(data.next_observations, next_actions), dim=1)
            next_q = th.min(next_q, dim=1, keepdim=True)[0] - ent_coef * next_log_prob.view(-1, 1)
            discounts = self.gamma if data.discounts is None else data.discounts
            target = data.rewards + (1 - data.dones) * discounts * next_q
        current = self.critic(data.observations, data.actions)
        return 0.5 * sum(F.mse_loss(q, target) for q in current)  # type: ignore[return-value]

    def actor_loss(
        self, obs: th.Tensor, actions: th.Tensor, log_prob: th.Tensor, ent_coef: th.Tensor
    ) -> th.Tensor:
        """SAC's actor loss ``mean(α log π(a|s) − min_k Q_k(s, a))`` with ``a ~ π(s)``."""
        q = th.cat(self.critic(obs, actions), dim=1)
        return (ent_coef * log_prob - th.min(q, dim=1, keepdim=True)[0]).mean()

    def _temperature(self, log_prob: th.Tensor) -> tuple[th.Tensor, float | None]:
        """α for this update, after SB3's temperature step when α is tuned; and that loss."""
        if self.ent_coef_optimizer is None or self.log_ent_coef is None:
            return self.ent_coef_tensor, None
        ent_coef = th.exp(self.log_ent_coef.detach())
        assert isinstance(self.target_entropy, float)
        loss = -(self.log_ent_coef * (log_prob + self.target_entropy).detach()).mean()
        self.ent_coef_optimizer.zero_grad()
        loss.backward()
        self.ent_coef_optimizer.step()
        return ent_coef, float(loss.item())

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        """`gradient_steps` RSC updates: the world model, then SAC on a mixed batch."""
        self.policy.set_training_mode(True)
        optimizers = [self.actor.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers.append(self.ent_coef_optimizer)
        self._update_learning_rate(optimizers)
        update_learning_rate(self.critic.optimizer, self.critic_learning_rate)
        logs: dict[str, list[float]] = defaultdict(list)
        for _ in range(gradient_steps):
            logs["model_loss"].append(self.update_world_model(batch_size, logs))
            data = self.mixed_batch(batch_size)
            self._sac_step(data, logs)
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        for name, values in logs.items():
            self.logger.record(f"train/{name}", float(np.mean(values)))
        self.logger.record(
            "train/graph_density", float(self.world_model.edge_probabilities().detach().mean())
        )
        self.logger.record("train/augmented_rows", self.augmented_rows(batch_size))

    def _sac_step(self, data: ReplayBufferSamples, logs: dict[str, list[float]]) -> None:
        """SB3's SAC update on `data`: temperature, critic, actor, then the soft target update."""
        if self.use_sde:
            self.actor.reset_noise()
        actions_pi, log_prob = self.actor.action_log_prob(data.observations)
        log_prob = log_prob.reshape(-1, 1)
        ent_coef, ent_loss = self._temperature(log_prob)
        logs["ent_coef"].append(float(ent_coef.item()))
        if ent_loss is not None:
            logs["ent_coef_loss"].append(ent_loss)
        critic_loss = self.critic_loss(data, ent_coef)
        self.critic.optimizer.zero_grad()
        critic_loss.backward()
        self.critic.optimizer.step()
        self.counts["critic"] += 1
        logs["critic_loss"].append(float(critic_loss.item()))
        actor_loss = self.actor_loss(data.observations, actions_pi, log_prob, ent_coef)
        self.actor.optimizer.zero_grad()
        actor_loss.backward()
        self.actor.optimizer.step()
        self.counts["actor"] += 1
        logs["actor_loss"].append(float(actor_loss.item()))
        if self._n_updates % self.target_update_interval == 0:
            polyak_update(self.critic.parameters(), self.critic_target.parameters(), self.tau)
            polyak_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)
        self._n_updates += 1
