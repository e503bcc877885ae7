"""LSTM learners: sb3-contrib's ``RecurrentPPO`` (the Stable-Baselines3 team's LSTM PPO).

An attacked MDP is partially observable for the agent: what it sees is not the state. ATLA's
most robust agents (Zhang et al. 2021) are therefore recurrent, so that memory can tell a lie
from the dynamics. `RecurrentPPOConfig` is `advgame.agents.PPOConfig` with an LSTM in front of
the actor and of the critic (``--algo recurrent-ppo``; methods ``atla-lstm``); its checkpoints
play as `advgame.agents.common.recurrent_policy.RecurrentSB3Policy`, which carries the memory across
the steps of an episode and zeroes it at every episode start.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from advgame.agents.sb3.config import PPOConfig

__all__ = ["RecurrentPPOConfig"]


@dataclass(frozen=True)
class RecurrentPPOConfig(PPOConfig):
    """PPO with LSTM policy and value networks (sb3-contrib ``RecurrentPPO``, ``MlpLstmPolicy``).

    The PPO fields keep `PPOConfig`'s meaning; `batch_size` counts steps, which sb3-contrib
    cuts into whole sequences per environment. The LSTM sits between the input and the
    `net_arch` layers of each network.
    """

    algo: ClassVar[str] = "recurrent-ppo"
    positive: ClassVar[tuple[str, ...]] = (
        "learning_rate",
        "n_steps",
        "n_epochs",
        "batch_size",
        "lstm_hidden_size",
        "n_lstm_layers",
    )
    hidden_optional: ClassVar[bool] = True
    net_arch: tuple[int, ...] = ()
    """Hidden layers after each LSTM; empty (ATLA's LSTM policies): the action mean and the
    value are linear read-outs of the LSTM's output."""
    lstm_hidden_size: int = 64
    """Units of each LSTM (ATLA's LSTM policies: 64)."""
    n_lstm_layers: int = 1
    """Stacked LSTM layers."""
    critic_lstm: bool = True
    """Give the value network its own LSTM (False: the critic is feed-forward)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        self._check_ints(("lstm_hidden_size", "n_lstm_layers"), 1)

    @staticmethod
    def model_class() -> Any:
        """The class that trains, saves and loads it: `UnrolledRecurrentPPO`.

        That is sb3-contrib's ``RecurrentPPO`` with each minibatch unrolled in one LSTM call
        (`advgame.agents.recurrent.ppo`); its files are sb3-contrib's.
        """
        from advgame.agents.recurrent.ppo import UnrolledRecurrentPPO

        return UnrolledRecurrentPPO

    def _recurrent_kwargs(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None
    ) -> dict[str, Any]:
        """``RecurrentPPO``'s keyword arguments from this config (flat observations only)."""
        from gymnasium import spaces

        from advgame.errors import ConfigError

        if isinstance(env.observation_space, spaces.Dict):
            raise ConfigError(
                f"{self.algo} takes flat (Box) observations, got {env.observation_space}; use "
                "--algo ppo or sac for goal-conditioned (Dict) tasks."
            )
        common = self._common(seed, total_steps, tensorboard_log)
        common["policy_kwargs"] = {
            **common["policy_kwargs"],
            "lstm_hidden_size": self.lstm_hidden_size,
            "n_lstm_layers": self.n_lstm_layers,
            "enable_critic_lstm": self.critic_lstm,
        }
        return {
            "n_steps": self.n_steps,
            "batch_size": self.batch_size,
            "n_epochs": self.n_epochs,
            "gae_lambda": self.gae_lambda,
            "clip_range": self.clip_range,
            "ent_coef": self.ent_coef,
            "vf_coef": self.vf_coef,
            "max_grad_norm": self.max_grad_norm,
            **common,
        }

    def make_model(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None = None
    ) -> Any:
        """Build a ``RecurrentPPO`` with ``MlpLstmPolicy`` on `env` (a VecEnv)."""
        return self.model_class()(
            "MlpLstmPolicy", env, **self._recurrent_kwargs(env, seed, total_steps, tensorboard_log)
        )
