"""DBC's learner config: the Robust Gymnasium paper's DBC parameters on `advgame.agents.dbc.dbc.DBC`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from advgame.agents.sb3.config import _OffPolicyConfig
from advgame.errors import ConfigError

__all__ = ["DBCConfig"]


@dataclass(frozen=True)
class DBCConfig(_OffPolicyConfig):
    """DBC (`advgame.agents.dbc.dbc.DBC`) with the Robust Gymnasium paper's DBC parameters.

    The paper gives DBC "the above parameters" (its RSC table: actor lr 3e-4, critic lr 1e-3,
    γ 0.99, τ 0.005, α 0.1 tuned at lr 3e-4, hidden [256, 256, 256], batch 128, replay 1e6)
    and encoder feature dim 256, encoder and decoder lr 1e-4, bisimulation coefficient 0.5, a
    probabilistic transition model and the actor's log std in [-10, 2]. The update schedule
    (actor and targets every 2nd update, encoder τ 0.005) and the start steps are the authors'.
    Continuous actions and flat observations only.
    """

    algo: ClassVar[str] = "dbc"
    positive: ClassVar[tuple[str, ...]] = (
        "learning_rate", "critic_learning_rate", "buffer_size", "batch_size", "encoder_lr",
        "decoder_lr",
    )  # fmt: skip
    learning_rate: float = 3e-4
    """Actor and temperature step size (paper: actor lr 3e-4, alpha lr 3e-4)."""
    critic_learning_rate: float = 1e-3
    """Critic step size; the critic's step also trains the encoder (paper: critic lr 1e-3)."""
    net_arch: tuple[int, ...] = (256, 256, 256)
    """Hidden layers of the actor and of each Q network on the encoding (paper: hidden size)."""
    learning_starts: int = 1000
    """Random steps before learning (the authors' ``init_steps``)."""
    batch_size: int = 128
    """Minibatch size of every update (paper: batch size 128)."""
    ent_coef: str = "auto_0.1"
    """Entropy temperature: SB3's ``"auto_<initial>"`` (paper: alpha 0.1, auto alpha)."""
    gradient_steps: int = 1
    """Updates per environment step (the authors': one)."""
    actor_update_interval: int = 2
    """Updates between actor and temperature updates (the authors' ``actor_update_freq``)."""
    target_update_interval: int = 2
    """Updates between target updates (the authors' ``critic_target_update_freq``)."""
    feature_dim: int = 256
    """Size of the encoding ``z = φ(s)`` (paper: encoder feature dim 256)."""
    encoder_arch: tuple[int, ...] = (256,)
    """Hidden ReLU layers of the encoder before its ``Linear → LayerNorm(feature_dim)``."""
    encoder_lr: float = 1e-4
    """Step size of the encoder on the bisimulation and model losses (paper: 1e-4)."""
    decoder_lr: float = 1e-4
    """Step size of the transition model and reward decoder (paper: decoder lr 1e-4)."""
    encoder_tau: float = 0.005
    """Update rate of the target encoder (the authors' ``encoder_tau``)."""
    bisim_coef: float = 0.5
    """Weight of the bisimulation loss beside the model losses (paper: bisim coef 0.5)."""
    model_width: int = 512
    """Hidden width of the transition model and the reward decoder (the authors': 512)."""
    log_std_min: float = -10.0
    """Lower bound of the actor's log std (paper: log std min -10)."""
    log_std_max: float = 2.0
    """Upper bound of the actor's log std (paper: log std max 2)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        ints = ("gradient_steps", "actor_update_interval", "target_update_interval",
                "feature_dim", "model_width")  # fmt: skip
        self._check_ints(ints, 1)
        if not all(type(w) is int and w > 0 for w in self.encoder_arch):
            raise ConfigError(
                f"DBCConfig.encoder_arch must be positive ints, got {self.encoder_arch!r}."
            )
        if not (isinstance(self.bisim_coef, (int, float)) and self.bisim_coef >= 0):
            raise ConfigError(f"DBCConfig.bisim_coef must be >= 0, got {self.bisim_coef!r}.")
        if not (isinstance(self.encoder_tau, (int, float)) and 0 < self.encoder_tau <= 1):
            raise ConfigError(f"DBCConfig.encoder_tau must be in (0, 1], got {self.encoder_tau!r}.")
        if not self.log_std_min < self.log_std_max:
            raise ConfigError(
                f"DBCConfig needs log_std_min < log_std_max, got {self.log_std_min!r} and "
                f"{self.log_std_max!r}."
            )

    @staticmethod
    def model_class() -> Any:
        """The SB3 class that trains (and resumes) it: `advgame.agents.dbc.dbc.DBC`."""
        from advgame.agents.dbc.dbc import DBC

        return DBC

    def make_model(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None = None
    ) -> Any:
        """Build a `DBC` on `env`; refuses what DBC cannot serve before anything trains."""
        self._require_state_control(env, "DBC")
        options = self._off_policy(seed, total_steps, tensorboard_log)
        options["policy_kwargs"].update(
            feature_dim=self.feature_dim, encoder_arch=list(self.encoder_arch),
            model_width=self.model_width, encoder_lr=self.encoder_lr,
            decoder_lr=self.decoder_lr, log_std_min=self.log_std_min,
            log_std_max=self.log_std_max,
        )  # fmt: skip
        return self.model_class()(
            "MlpPolicy", env, train_freq=1, gradient_steps=self.gradient_steps,
            ent_coef=self.ent_coef, target_update_interval=self.target_update_interval,
            actor_update_interval=self.actor_update_interval, bisim_coef=self.bisim_coef,
            critic_learning_rate=self.critic_learning_rate, encoder_tau=self.encoder_tau,
            **options,
        )  # fmt: skip
