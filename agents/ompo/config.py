"""OMPO's learner config: the Robust Gymnasium paper's OMPO table on `advgame.agents.ompo.ompo.OMPO`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from advgame.agents.sb3.config import _OffPolicyConfig
from advgame.errors import ConfigError

__all__ = ["OMPOConfig"]


@dataclass(frozen=True)
class OMPOConfig(_OffPolicyConfig):
    """OMPO (`advgame.agents.ompo.ompo.OMPO`) with the Robust Gymnasium paper's OMPO table.

    Start steps 5,000, batch 256, 3 updates per environment step, actor and targets every 2nd
    update, hidden [256, 256] (LayerNorm + tanh, then ELU), lr 3e-4, τ 0.005, α 0.2 tuned
    automatically, discriminator batch 256, exponent 1.5, tomac alpha 1e-3, reward max 1, a
    local set of 1,000 transitions. Continuous actions and flat observations only.
    """

    algo: ClassVar[str] = "ompo"
    learning_rate: float = 3e-4
    """Actor, critic and temperature step size."""
    net_arch: tuple[int, ...] = (256, 256)
    """Hidden layer sizes (OMPO: hidden size 256)."""
    learning_starts: int = 5000
    """Random steps before learning (OMPO: start steps 5000)."""
    batch_size: int = 256
    """Minibatch size of the agent's updates."""
    ent_coef: str = "auto_0.2"
    """Entropy temperature: SB3's ``"auto_<initial>"`` (OMPO: α 0.2, automatic tuning)."""
    gradient_steps: int = 3
    """Updates per environment step (OMPO: updates per step 3)."""
    target_update_interval: int = 2
    """Updates between actor, temperature and target updates."""
    local_size: int = 1000
    """Local transitions per discriminator training (OMPO: local replay size 1000)."""
    disc_batch: int = 256
    """Discriminator minibatch (OMPO: gail batch 256)."""
    exponent: float = 1.5
    """``p`` of the critic's power loss ``|y − Q|^p / p``."""
    tomac_alpha: float = 1e-3
    """Weight of the discriminator's reward correction and of the initial-state term."""
    correction_weight: float | None = None
    """Weight of the reward correction alone (None: `tomac_alpha`, OMPO's): 0 is the ablation
    without it, a larger one makes it a stated share of the reward (docs/ompo.md)."""
    reward_max: float = 1.0
    """Shift added to rewards before the clamp at 1e-6."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.exponent > 1:
            raise ConfigError(f"OMPOConfig.exponent must be > 1, got {self.exponent!r}.")
        weight = self.correction_weight
        if weight is not None and not (isinstance(weight, (int, float)) and weight >= 0):
            raise ConfigError(
                f"OMPOConfig.correction_weight must be a number >= 0 or None, got {weight!r}."
            )
        self._check_ints(
            ("gradient_steps", "target_update_interval", "local_size", "disc_batch"), 1
        )

    @staticmethod
    def model_class() -> Any:
        """The SB3 class that trains (and resumes) it: `advgame.agents.ompo.ompo.OMPO`."""
        from advgame.agents.ompo.ompo import OMPO

        return OMPO

    def make_model(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None = None
    ) -> Any:
        """Build an `OMPO` on `env`; refuses what OMPO cannot serve before anything trains."""
        self._require_state_control(env, "OMPO")
        return self.model_class()(
            "MlpPolicy", env, train_freq=1, gradient_steps=self.gradient_steps,
            ent_coef=self.ent_coef, target_update_interval=self.target_update_interval,
            local_size=self.local_size, disc_batch=self.disc_batch, exponent=self.exponent,
            tomac_alpha=self.tomac_alpha, correction_weight=self.correction_weight,
            reward_max=self.reward_max,
            **self._off_policy(seed, total_steps, tensorboard_log),
        )  # fmt: skip
