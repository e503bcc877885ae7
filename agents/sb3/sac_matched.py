"""SB3's SAC with another method's step sizes and update schedule: the ``sac-*-matched`` controls.

A control beside a method (`advgame.training.METHODS`: ``sac-rsc-matched``,
``sac-dbc-matched``, ``sac-ompo-matched``) must learn as that method does but for the method
itself. SB3's SAC already takes the networks, batch, n-step returns (``n_steps``, SB3 >= 2.7),
temperature and updates per step; `MatchedSAC` adds the two things RSC, DBC and OMPO do that
it does not:

* **A critic step size of its own** (`critic_learning_rate`: RSC's and DBC's 1e-3 beside the
  actor's and the temperature's 3e-4); None is SB3's one rate for all three.
* **The actor every k-th update** (`actor_update_interval`: DBC's and OMPO's 2). On the other
  updates only the critics learn, with SB3's loss at the current temperature; on the k-th, SB3's
  own update runs (temperature, critics, actor, then the soft target update), so the
  temperature and the targets move with the actor, as in both methods.

With both at their defaults it is SB3's SAC bit for bit (a test checks it).
"""

from __future__ import annotations

import warnings
from typing import Any

import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.utils import update_learning_rate
from torch.nn import functional as F

__all__ = ["MatchedSAC"]


class MatchedSAC(SAC):
    """SB3's SAC with its own critic step size and an actor update every k-th update.

    Args beyond SAC's:
        critic_learning_rate: the critics' Adam step size, constant (None: SB3's one rate).
        actor_update_interval: updates between two of the actor, temperature and targets.
    """

    def __init__(
        self,
        policy: Any,
        env: Any,
        *,
        critic_learning_rate: float | None = None,
        actor_update_interval: int = 1,
        _init_setup_model: bool = True,
        **kwargs: Any,
    ) -> None:
        self.critic_learning_rate = critic_learning_rate
        self.actor_update_interval = actor_update_interval
        super().__init__(policy, env, _init_setup_model=_init_setup_model, **kwargs)

    def _setup_model(self) -> None:
        with warnings.catch_warnings():
            if "n_steps" in self.replay_buffer_kwargs:  # a loaded model's n-step buffer is set
                warnings.filterwarnings("ignore", message="`n_steps=", category=UserWarning)
            super()._setup_model()

    def _update_learning_rate(self, optimizers: Any) -> None:
        super()._update_learning_rate(optimizers)
        if self.critic_learning_rate is not None:
            update_learning_rate(self.critic.optimizer, self.critic_learning_rate)

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        """SB3's updates, the actor's (with the temperature and the targets) every k-th only."""
        k = self.actor_update_interval
        if k == 1:
            return super().train(gradient_steps, batch_size)
        for _ in range(gradient_steps):
            if self._n_updates % k == 0:
                super().train(1, batch_size)
            else:
                self.critic_step(batch_size)

    def critic_step(self, batch_size: int) -> float:
        """One update of the critics alone, SB3's loss at the current temperature; its loss."""
        self.policy.set_training_mode(True)
        self._update_learning_rate([self.critic.optimizer])
        data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
        discounts = data.discounts if data.discounts is not None else self.gamma
        log_alpha = self.log_ent_coef
        alpha = th.exp(log_alpha.detach()) if log_alpha is not None else self.ent_coef_tensor
        with th.no_grad():
            actions, log_prob = self.actor.action_log_prob(data.next_observations)
            nxt = th.cat(self.critic_target(data.next_observations, actions), dim=1)
            nxt = th.min(nxt, dim=1, keepdim=True)[0] - alpha * log_prob.reshape(-1, 1)
            target = data.rewards + (1 - data.dones) * discounts * nxt
        loss = 0.5 * sum(
            F.mse_loss(q, target) for q in self.critic(data.observations, data.actions)
        )
        self.critic.optimizer.zero_grad()
        loss.backward()  # type: ignore[union-attr]
        self.critic.optimizer.step()
        self._n_updates += 1
        return float(loss.item())  # type: ignore[union-attr]
