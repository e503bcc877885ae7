"""Stable-Baselines3 learners with the paper's hyper-parameters as presets.

Each config is a frozen dataclass; `make_model` builds the SB3 model on a VecEnv of
single-agent views. The same configs train adversaries (PPO, SAC) in the adversary phase.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from advgame.core.registry import load
from advgame.errors import ConfigError

__all__ = [
    "LinearDecay",
    "PPOConfig",
    "SACConfig",
    "TD3Config",
]


class LinearDecay:
    """Learning rate decaying linearly to 0 over a whole alternating run.

    SB3 gives a schedule ``progress_remaining = 1 − t / (t₀ + n)`` in a ``learn(n)`` call begun
    at step ``t₀`` (``reset_num_timesteps=False``), so it reaches 0 at the end of every call.
    Whoever calls ``learn`` sets `offset` (``t₀``, the model's step count before the call) and
    `span` (``n``); the step the schedule is at is then ``(1 − progress_remaining)(t₀ + n)``
    and the rate ``initial · (1 − t / total)``, the same however the run is cut into calls.
    (Until 27 Nov it read ``t₀ + (1 − progress_remaining) n``, as if SB3 restarted its counter
    per call: a call's rate then lagged by up to its own length, about 1 % of the initial rate
    in a 122-iteration run and up to 19 % in the four chunks of a best response.)
    """

    def __init__(self, initial: float, total: int) -> None:
        self.initial = initial
        self.total = max(int(total), 1)
        self.offset = 0
        self.span = self.total

    def __call__(self, progress_remaining: float) -> float:
        """The learning rate at SB3's `progress_remaining` of the current ``learn()`` call."""
        done = (1.0 - progress_remaining) * (self.offset + self.span)
        return self.initial * max(1.0 - done / self.total, 0.0)


@dataclass(frozen=True)
class _SB3Config:
    """What every SB3 learner config has; subclasses set their own defaults."""

    algo: ClassVar[str] = ""
    positive: ClassVar[tuple[str, ...]] = ("learning_rate",)
    hidden_optional: ClassVar[bool] = False
    """Whether `net_arch` may be empty (a recurrent policy reads its actions off the LSTM)."""
    learning_rate: float = 3e-4
    """Adam step size (actor and critic)."""
    lr_decay: bool = False
    """Decay the learning rate linearly to 0 over the run."""
    gamma: float = 0.99
    """Discount factor."""
    net_arch: tuple[int, ...] = (64, 64)
    """Hidden layer sizes of the policy and value networks."""

    def __post_init__(self) -> None:
        for name in self.positive:
            value = getattr(self, name)
            if not value > 0:
                raise ConfigError(f"{type(self).__name__}.{name} must be > 0, got {value!r}.")
        arch = self.net_arch
        if (
            not isinstance(arch, (tuple, list))
            or not (arch or self.hidden_optional)
            or not all(type(h) is int and h > 0 for h in arch)
        ):
            empty = " (or empty)" if self.hidden_optional else ""
            raise ConfigError(
                f"{type(self).__name__}.net_arch must be positive ints{empty}, got {arch!r}."
            )

    def _check_ints(self, names: tuple[str, ...], minimum: int) -> None:
        """Each of the fields `names` must be an int >= `minimum` (a clear error otherwise)."""
        for name in names:
            value = getattr(self, name)
            if type(value) is not int or value < minimum:
                raise ConfigError(
                    f"{type(self).__name__}.{name} must be an int >= {minimum}, got {value!r}."
                )

    @staticmethod
    def policy(env: Any) -> str:
        """SB3's policy class name for `env`: ``MultiInputPolicy`` for Dict observations."""
        from gymnasium import spaces

        return "MultiInputPolicy" if isinstance(env.observation_space, spaces.Dict) else "MlpPolicy"

    def _common(self, seed: int, total_steps: int, tensorboard_log: str | None) -> dict[str, Any]:
        """Keyword arguments every SB3 algorithm takes, from this config."""
        lr: Any = (
            LinearDecay(self.learning_rate, total_steps) if self.lr_decay else self.learning_rate
        )
        return {
            "learning_rate": lr,
            "gamma": self.gamma,
            "seed": seed,
            "device": "cpu",
            "verbose": 0,
            "tensorboard_log": tensorboard_log,
            # foreach Adam: fewer kernels than the default loop, and unlike the fused kernel it
            # marks the parameters it updates (their ``_version``), which NumPy copies of a
            # live learner check (`advgame.core.numpy_net.weights_stamp`; bench_adam.py)
            "policy_kwargs": {
                "net_arch": list(self.net_arch),
                "optimizer_kwargs": {"foreach": True},
            },
        }


@dataclass(frozen=True)
class PPOConfig(_SB3Config):
    """PPO with the paper's table (PPO/MAPPO/IPPO hyper-parameters)."""

    algo: ClassVar[str] = "ppo"
    positive: ClassVar[tuple[str, ...]] = ("learning_rate", "n_steps", "n_epochs", "batch_size")
    lr_decay: bool = True
    """Decay the learning rate linearly to 0 over the run (paper: lr decay True)."""
    gae_lambda: float = 0.95
    """GAE λ."""
    clip_range: float = 0.2
    """PPO ratio clip ε."""
    n_steps: int = 2048
    """Steps per environment per rollout (paper: 2048 steps per collect)."""
    n_epochs: int = 10
    """Optimisation epochs per rollout (paper: repeat per collect 10)."""
    batch_size: int = 64
    """Minibatch size."""
    vf_coef: float = 0.25
    """Value loss coefficient."""
    ent_coef: float = 0.0
    """Entropy bonus coefficient."""
    max_grad_norm: float = 0.5
    """Gradient clipping norm."""

    def make_model(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None = None
    ) -> Any:
        """Build an SB3 PPO on `env` (a VecEnv)."""
        from stable_baselines3 import PPO

        return PPO(
            self.policy(env),
            env,
            n_steps=self.n_steps,
            batch_size=self.batch_size,
            n_epochs=self.n_epochs,
            gae_lambda=self.gae_lambda,
            clip_range=self.clip_range,
            ent_coef=self.ent_coef,
            vf_coef=self.vf_coef,
            max_grad_norm=self.max_grad_norm,
            **self._common(seed, total_steps, tensorboard_log),
        )


@dataclass(frozen=True)
class _OffPolicyConfig(_SB3Config):
    """What SAC and TD3 share: a replay buffer and soft target updates."""

    positive: ClassVar[tuple[str, ...]] = ("learning_rate", "buffer_size", "batch_size")
    learning_rate: float = 1e-3
    """Actor and critic step size."""
    tau: float = 0.005
    """Target network update rate."""
    buffer_size: int = 1_000_000
    """Replay buffer size (SB3's default; the paper's table lists 4096)."""
    learning_starts: int = 10_000
    """Random steps before learning (paper: start time step 10000)."""
    batch_size: int = 64
    """Minibatch size."""

    @staticmethod
    def _require_state_control(env: Any, method: str) -> None:
        """Refuse, before anything trains, a task `method` cannot serve.

        It needs continuous (Box) actions and flat (1-D Box) observations.
        """
        from gymnasium import spaces

        act, obs = env.action_space, env.observation_space
        if not (
            isinstance(act, spaces.Box) and isinstance(obs, spaces.Box) and len(obs.shape) == 1
        ):
            raise ConfigError(
                f"{method} needs continuous (Box) actions and flat (1-D Box) observations, got "
                f"actions {act} and observations {obs}; it serves single-agent tasks with state "
                "observations (e.g. Hopper-v5, InvertedPendulum-v5). Use --method sac or ppo here."
            )

    def _off_policy(
        self, seed: int, total_steps: int, tensorboard_log: str | None
    ) -> dict[str, Any]:
        return {
            "buffer_size": self.buffer_size,
            "learning_starts": self.learning_starts,
            "batch_size": self.batch_size,
            "tau": self.tau,
            **self._common(seed, total_steps, tensorboard_log),
        }


_GOALS = ("future", "final", "episode")
"""HER's goal selection strategies."""


@dataclass(frozen=True)
class SACConfig(_OffPolicyConfig):
    """SAC with the paper's table (fixed temperature α = 0.2, [64, 64], lr 1e-3, batch 64).

    Its last four fields let it learn as another method does: the ``sac-*-matched`` controls.
    """

    algo: ClassVar[str] = "sac"
    ent_coef: float | str = 0.2
    """Entropy temperature α: fixed (the paper's auto alpha is False) or ``"auto_<initial>"``."""
    train_freq: int = 1
    """Environment steps between updates."""
    gradient_steps: int = 1
    """Updates per training call (paper: update per step 1)."""
    her: bool = False
    """Hindsight experience replay for goal-conditioned views (Dict observations with
    ``achieved_goal``/``desired_goal``): `advgame.agents.sb3.her.TrueGoalHerReplayBuffer`, which
    relabels with the task's true goals even under an observation attack."""
    her_n_sampled_goal: int = 4
    """HER: virtual transitions per real one."""
    her_goal_selection: str = "future"
    """HER: where new goals come from, ``"future"``, ``"final"`` or ``"episode"``."""
    critic_learning_rate: float | None = None
    """The critics' Adam step size (None: `learning_rate`, as SB3's SAC), constant."""
    n_steps: int = 1
    """Steps of the critic's returns (SB3's n-step replay buffer; 1: one-step)."""
    actor_update_interval: int = 1
    """Updates between two of the actor, temperature and targets (OMPO's and DBC's: 2)."""
    networks: str = "sb3"
    """``"sb3"`` (ReLU MLPs) or ``"ompo"`` (OMPO's: `advgame.agents.ompo.nets.OMPOPolicy`)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        alpha, rate = self.ent_coef, self.critic_learning_rate
        auto = isinstance(alpha, str) and (alpha == "auto" or alpha.startswith("auto_"))
        number = isinstance(alpha, (int, float)) and not isinstance(alpha, bool)
        plain = self.n_steps == 1 and self.networks == "sb3"
        checks = {
            "her_goal_selection": (self.her_goal_selection in _GOALS, f"one of {_GOALS}"),
            "her_n_sampled_goal": (self.her_n_sampled_goal >= 1, ">= 1"),
            "ent_coef": (auto or number, "a number or 'auto_<initial>' (e.g. 'auto_0.1')"),
            "critic_learning_rate": (rate is None or rate > 0, "> 0 or None"),
            "networks": (self.networks in ("sb3", "ompo"), "'sb3' or 'ompo'"),
            "her": (plain or not self.her, "False with n_steps > 1 or networks 'ompo'"),
        }
        for name, (ok, expected) in checks.items():
            if not ok:
                value = getattr(self, name)
                raise ConfigError(f"SACConfig.{name} must be {expected}, got {value!r}.")
        self._check_ints(("n_steps", "actor_update_interval", "train_freq", "gradient_steps"), 1)

    @staticmethod
    def model_class() -> Any:
        """The SB3 class that trains (and resumes) it: `advgame.agents.sb3.sac_matched.MatchedSAC`."""
        from advgame.agents.sb3.sac_matched import MatchedSAC

        return MatchedSAC

    def make_model(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None = None
    ) -> Any:
        """Build a `MatchedSAC` on `env` (``MultiInputPolicy`` on Dict observations)."""
        ompo = self.networks == "ompo"
        policy = load("advgame.agents.ompo.nets:OMPOPolicy") if ompo else self.policy(env)
        return self.model_class()(
            policy, env, train_freq=self.train_freq, gradient_steps=self.gradient_steps,
            ent_coef=self.ent_coef, n_steps=self.n_steps,
            critic_learning_rate=self.critic_learning_rate,
            actor_update_interval=self.actor_update_interval,
            **self._her(env), **self._off_policy(seed, total_steps, tensorboard_log),
        )  # fmt: skip

    def _her(self, env: Any) -> dict[str, Any]:
        """The replay-buffer arguments HER needs (none without it)."""
        if not self.her:
            return {}
        keys = getattr(env.observation_space, "spaces", {})
        if not {"achieved_goal", "desired_goal"} <= set(keys):
            raise ConfigError(
                f"SACConfig(her=True) needs a goal-conditioned Dict observation with "
                f"'achieved_goal' and 'desired_goal', got {env.observation_space}; use a Fetch, "
                "Hand or Maze scenario, or her=False."
            )
        from advgame.agents.sb3.her import TrueGoalHerReplayBuffer

        return {
            "replay_buffer_class": TrueGoalHerReplayBuffer,
            "replay_buffer_kwargs": {
                "n_sampled_goal": self.her_n_sampled_goal,
                "goal_selection_strategy": self.her_goal_selection,
            },
        }


@dataclass(frozen=True)
class TD3Config(_OffPolicyConfig):
    """TD3 (SB3's defaults: [256, 256], batch 256), Gaussian exploration noise σ = 0.1."""

    algo: ClassVar[str] = "td3"
    net_arch: tuple[int, ...] = (256, 256)
    """Hidden layer sizes."""
    batch_size: int = 256
    """Minibatch size."""
    action_noise: float = 0.1
    """Std of the Gaussian exploration noise, as a fraction of the action range."""
    policy_delay: int = 2
    """Critic updates per actor update."""

    def make_model(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None = None
    ) -> Any:
        """Build an SB3 TD3 on `env`."""
        import numpy as np
        from stable_baselines3 import TD3
        from stable_baselines3.common.noise import NormalActionNoise

        n = env.action_space.shape[-1]
        half = (env.action_space.high - env.action_space.low) / 2.0
        noise = NormalActionNoise(np.zeros(n), self.action_noise * half * np.ones(n))
        return TD3(
            self.policy(env),
            env,
            policy_delay=self.policy_delay,
            action_noise=noise,
            **self._off_policy(seed, total_steps, tensorboard_log),
        )
