"""ATLA-LSTM-SA's learner config: `RecurrentPPOConfig` plus `SAPPOConfig`'s regulariser fields."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from advgame.agents.recurrent.config import RecurrentPPOConfig
from advgame.agents.sb3.config import SAPPOConfig

__all__ = ["SARecurrentPPOConfig"]


@dataclass(frozen=True)
class SARecurrentPPOConfig(RecurrentPPOConfig, SAPPOConfig):
    """An LSTM PPO with the state-adversarial regulariser (`advgame.agents.sa.recurrent`).

    The fields and checks of `RecurrentPPOConfig` and of `SAPPOConfig` (both inherited, so
    both validate), with the ATLA-LSTM-SA Hopper defaults: κ = 0.6 (ATLA's 0.3 on its term,
    which is twice our KL, see `advgame.agents.sa.recurrent`), ε = 0.075 in normalized units (Walker2d:
    0.05), 2 PGD steps per minibatch, ε ramped up over the first 75 % of the run. Selected as
    ``--protagonist-algo sa-recurrent-ppo`` (method ``atla-lstm-sa``); like SA-PPO's, its
    checkpoints are plain files of the learner it extends: ``algo`` stays ``"recurrent-ppo"``,
    so a saved agent plays as an LSTM policy.
    """

    sa_kappa: float = 0.6
    """κ: weight of the regulariser on the KL (ATLA-LSTM-SA's 0.3 on twice the KL)."""
    sa_steps: int = 2
    """PGD steps of the inner maximisation per minibatch (ATLA-LSTM-SA: 2)."""

    @staticmethod
    def model_class() -> Any:
        """The class that trains and resumes it: `advgame.agents.sa.recurrent.SARecurrentPPO`."""
        from advgame.agents.sa.recurrent import SARecurrentPPO

        return SARecurrentPPO

    def make_model(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None = None
    ) -> Any:
        """Build an `SARecurrentPPO` with ``MlpLstmPolicy`` on `env` (a VecEnv)."""
        return self.model_class()(
            "MlpLstmPolicy", env, sa_kappa=self.sa_kappa, sa_eps=self.sa_eps,
            sa_steps=self.sa_steps, sa_ramp=self.sa_ramp, sa_space=self.sa_space,
            sa_total_steps=total_steps,
            **self._recurrent_kwargs(env, seed, total_steps, tensorboard_log),
        )  # fmt: skip
