"""RSC's learner config: the Robust Gymnasium paper's RSC table on `advgame.agents.rsc.rsc.RSC`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from advgame.agents.sb3.config import _OffPolicyConfig
from advgame.errors import ConfigError

__all__ = ["RSCConfig"]


@dataclass(frozen=True)
class RSCConfig(_OffPolicyConfig):
    """RSC (`advgame.agents.rsc.rsc.RSC`) with the Robust Gymnasium paper's RSC table.

    Actor lr 3e-4, critic lr 1e-3, τ 5e-3, γ 0.99, α 0.1 tuned automatically (temperature lr
    3e-4), hidden [256, 256, 256], n-step 4, batch 128, buffer 1e6, start time step 0, sigma
    0.01, bound 0.01, augmented ratio 0.5, vae sigma 1.0. The world model's own settings are
    ours (the paper gives none). Continuous actions and flat observations only.
    """

    algo: ClassVar[str] = "rsc"
    positive: ClassVar[tuple[str, ...]] = (
        "learning_rate", "critic_learning_rate", "buffer_size", "batch_size", "vae_sigma",
        "model_lr", "graph_lr", "temperature",
    )  # fmt: skip
    learning_rate: float = 3e-4
    """Actor and temperature step size (RSC: actor lr 3e-4, alpha lr 3e-4)."""
    critic_learning_rate: float = 1e-3
    """Critic step size (RSC: critic lr 1e-3); constant, also under ``lr_decay``."""
    net_arch: tuple[int, ...] = (256, 256, 256)
    """Hidden layer sizes of the actor and of each critic (RSC: hidden size [256, 256, 256])."""
    learning_starts: int = 0
    """Random steps before learning (RSC: start time step 0)."""
    batch_size: int = 128
    """SAC minibatch, real and augmented rows together; also the world model's batch."""
    ent_coef: str = "auto_0.1"
    """Entropy temperature: SB3's ``"auto_<initial>"`` (RSC: α 0.1, auto alpha True)."""
    n_steps: int = 4
    """Steps of the real rows' returns (RSC: n step 4; SB3's n-step replay buffer)."""
    train_freq: int = 1
    """Environment steps between updates."""
    gradient_steps: int = 1
    """Updates per training call."""
    augmented_ratio: float = 0.5
    """Share of each SAC batch made of augmented transitions (RSC: augmented ratio 0.5)."""
    sigma: float = 0.01
    """Standard deviation of the Gaussian jitter added to augmented states (RSC: sigma)."""
    bound: float = 0.01
    """Clip of that jitter, per dimension (RSC: bound)."""
    vae_sigma: float = 1.0
    """Standard deviation of the world model's Gaussian likelihood (RSC: vae sigma)."""
    model_hidden: int = 64
    """Width of the world model's per-output hidden layers (ours)."""
    model_lr: float = 1e-3
    """The world model networks' Adam step size (ours)."""
    graph_lr: float = 3e-2
    """The causal graph logits' Adam step size (ours)."""
    sparsity: float = 3e-3
    """λ: weight of the graph's sparsity term in the world-model loss (ours; on −log P(edge absent)
    with hard draws, on the expected number of edges with relaxed ones)."""
    temperature: float = 1.0
    """τ of the Gumbel-Softmax draws of the graph (ours)."""
    model_warmup: int = 1000
    """World-model updates before the first augmented transition (ours)."""
    graph_draws: str = "hard"
    """How the world model's loss draws each row's graph (ours): ``"hard"``, Bernoulli edges
    with the score function's gradient, or ``"relaxed"``, Gumbel-Softmax draws, which let an
    edge's logit die while the masked input still informs its output (docs/causal.md, "The
    graph's draws"; the RS-LiftCausal runs before 6 Dec trained so)."""
    keep_self_edges: bool = True
    """Give every state output its own past, ``s[i] → s'[i]``, as an edge always present (ours:
    a variable's persistence is never the spurious correlation RSC breaks; without it the graph
    may predict a variable from a correlated stand-in, e.g. the cube's colour from its side,
    and then an augmented colour does not stay the colour)."""

    clip_to_support: bool = False
    """Clip each augmented next-state and reward dimension to the range of the world model's
    training targets (ours; docs/causal.md, "The door's first RSC run diverged"; the door
    campaign sets it, the lift campaign's runs trained without it)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not (isinstance(self.augmented_ratio, (int, float)) and 0 <= self.augmented_ratio <= 1):
            raise ConfigError(
                f"RSCConfig.augmented_ratio must be in [0, 1], got {self.augmented_ratio!r}."
            )
        for name in ("sigma", "bound", "sparsity"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value >= 0):
                raise ConfigError(f"RSCConfig.{name} must be a number >= 0, got {value!r}.")
        self._check_ints(("n_steps", "train_freq", "gradient_steps", "model_hidden"), 1)
        self._check_ints(("learning_starts", "model_warmup"), 0)

    @staticmethod
    def model_class() -> Any:
        """The SB3 class that trains (and resumes) it: `advgame.agents.rsc.rsc.RSC`."""
        from advgame.agents.rsc.rsc import RSC

        return RSC

    def make_model(
        self, env: Any, seed: int, total_steps: int, tensorboard_log: str | None = None
    ) -> Any:
        """Build an `RSC` on `env`; refuses what RSC cannot serve before anything trains."""
        self._require_state_control(env, "RSC")
        return self.model_class()(
            "MlpPolicy", env, train_freq=self.train_freq, gradient_steps=self.gradient_steps,
            ent_coef=self.ent_coef, n_steps=self.n_steps,
            critic_learning_rate=self.critic_learning_rate, augmented_ratio=self.augmented_ratio,
            sigma=self.sigma, bound=self.bound, vae_sigma=self.vae_sigma,
            model_hidden=self.model_hidden, model_lr=self.model_lr, graph_lr=self.graph_lr,
            sparsity=self.sparsity, temperature=self.temperature, model_warmup=self.model_warmup,
            graph_draws=self.graph_draws, keep_self_edges=self.keep_self_edges,
            clip_to_support=self.clip_to_support,
            **self._off_policy(seed, total_steps, tensorboard_log),
        )  # fmt: skip
