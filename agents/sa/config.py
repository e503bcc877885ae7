"""SA-PPO's learner configs: `SAPPOConfig` (PPO plus the regulariser) and ATLA-LSTM-SA's `SARecurrentPPOConfig`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from advgame.agents.recurrent.config import RecurrentPPOConfig
from advgame.agents.sb3.config import PPOConfig
from advgame.errors import ConfigError

__all__ = ["SAPPOConfig", "SARecurrentPPOConfig"]


@dataclass(frozen=True)
class SAPPOConfig(PPOConfig):
    """SA-PPO: `PPOConfig` plus the state-adversarial regulariser (`advgame.agents.sa.ppo`).

    Defaults are the SA-PPO/ATLA Hopper configs: κ = 0.2 (their 0.1 weighs Σ((μ̂ − μ)/σ)², which
    is twice the KL this regulariser uses), ε = 0.075 in normalized units, 10 PGD steps, ε
    ramped up over the first 75 % of the run. Its checkpoints are plain PPO files.
    """

    sa_kappa: float = 0.2
    """κ: weight of the regulariser on the KL (ATLA's SA-PPO configs: 0.1 on twice the KL)."""
    sa_eps: float = 0.075
    """ε: the L∞ radius of the ball, in `sa_space` units (use the threat model's budget)."""
    sa_steps: int = 10
    """PGD steps of the inner maximisation per minibatch."""
    sa_ramp: float = 0.75
    """Fraction of the run over which ε grows linearly from 0 (0: full ε from the start)."""
    sa_space: str = "normalized"
    """``"normalized"`` (the policy's VecNormalize input, ATLA's budgets) or ``"raw"``."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not (isinstance(self.sa_kappa, (int, float)) and self.sa_kappa >= 0):
            raise ConfigError(
                f"{type(self).__name__}.sa_kappa must be >= 0, got {self.sa_kappa!r}."
            )
        if not (isinstance(self.sa_eps, (int, float)) and self.sa_eps >= 0):
            raise ConfigError(f"{type(self).__name__}.sa_eps must be >= 0, got {self.sa_eps!r}.")
        self._check_ints(("sa_steps",), 0)
        if not (isinstance(self.sa_ramp, (int, float)) and 0 <= self.sa_ramp <= 1):
            raise ConfigError(
                f"{type(self).__name__}.sa_ramp must be in [0, 1], got {self.sa_ramp!r}."
            )
        if self.sa_space not in ("normalized", "raw"):
            raise ConfigError(
                f"{type(self).__name__}.sa_space must be 'normalized' or 'raw', got {self.sa_space!r}."
            )

    @staticmethod
    def model_class() -> Any:
        """The SB3 class that trains (and resumes) it: `advgame.agents.sa.ppo.SAPPO`."""
        from advgame.agents.sa.ppo import SAPPO

        return SAPPO

    def make_model(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None = None
    ) -> Any:
        """Build an `SAPPO` on `env` (a VecEnv)."""
        return self.model_class()(
            self.policy(env), env, n_steps=self.n_steps, batch_size=self.batch_size,
            n_epochs=self.n_epochs, gae_lambda=self.gae_lambda, clip_range=self.clip_range,
            ent_coef=self.ent_coef, vf_coef=self.vf_coef, max_grad_norm=self.max_grad_norm,
            sa_kappa=self.sa_kappa, sa_eps=self.sa_eps, sa_steps=self.sa_steps,
            sa_ramp=self.sa_ramp, sa_space=self.sa_space, sa_total_steps=total_steps,
            **self._common(seed, total_steps, tensorboard_log),
        )  # fmt: skip


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
