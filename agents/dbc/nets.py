"""DBC's networks as a Stable-Baselines3 SAC policy: a learned encoder shared by critic and actor.

Deep Bisimulation for Control (Zhang et al., ICLR 2021; the authors' code is
``facebookresearch/deep_bisim4control``: ``encoder.py``, ``transition_model.py``, ``sac_ae.py``,
``agent/bisim_agent.py``) learns an encoding ``z = φ(s)`` whose distances follow a
bisimulation metric. `DBCPolicy` is SB3's `SACPolicy` built around that encoding:

* **Encoder** (`BisimEncoder`): an MLP then ``Linear → LayerNorm`` to `feature_dim`. The
  authors' state-observation encoder is the identity (no parameters, so the bisimulation loss
  could shape nothing); this one is learned, ending like their pixel encoder (``fc → ln``).
  It is the critic's features extractor: the critic's loss trains it (the critic's optimizer
  holds it, as in the authors' code), and so do the bisimulation and model losses.
* **Target encoder**: the target critic's own copy, moved towards the encoder at `encoder_tau`.
* **Actor** (`DBCActor`): SB3's squashed Gaussian on the *detached* encoding of the same
  encoder (its optimizer does not hold the encoder), with the authors' log std: ``tanh``
  rescaled into ``[log_std_min, log_std_max]`` = [-10, 2] instead of SB3's clamp to [-20, 2].
* **Transition model** (`GaussianTransition`): ``(z, a) → Linear → LayerNorm → ReLU →`` a mean
  and a std ``σ = σ_min + (σ_max − σ_min)·sigmoid(·)`` with σ in (1e-4, 10), the authors'
  ``ProbabilisticTransitionModel``.
* **Reward decoder**: ``z' → Linear → LayerNorm → ReLU → Linear → r``.

The encoder's and the decoder's (transition model and reward decoder) optimizers live on the
policy; `advgame.agents.dbc.dbc.DBC` saves them with the model.
"""

from __future__ import annotations

from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.preprocessing import get_flattened_obs_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.sac.policies import Actor, SACPolicy
from torch import nn

__all__ = ["BisimEncoder", "DBCActor", "DBCPolicy", "GaussianTransition", "reward_decoder"]


class BisimEncoder(BaseFeaturesExtractor):
    """φ(s): an MLP (ReLU hidden layers `hidden`) ending in ``Linear → LayerNorm(feature_dim)``."""

    def __init__(
        self, observation_space: spaces.Space, feature_dim: int = 256, hidden: Any = (256,)
    ) -> None:
        super().__init__(observation_space, feature_dim)
        layers: list[nn.Module] = [nn.Flatten()]
        last = get_flattened_obs_dim(observation_space)
        for width in hidden:
            layers += [nn.Linear(last, int(width)), nn.ReLU()]
            last = int(width)
        layers += [nn.Linear(last, feature_dim), nn.LayerNorm(feature_dim)]
        self.net = nn.Sequential(*layers)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        """The encoding of a batch of observations."""
        return self.net(observations)


class GaussianTransition(nn.Module):
    """P̂(z' | z, a): a diagonal Gaussian with σ squashed into ``(min_sigma, max_sigma)``."""

    def __init__(
        self,
        feature_dim: int,
        action_dim: int,
        width: int = 512,
        min_sigma: float = 1e-4,
        max_sigma: float = 10.0,
    ) -> None:
        super().__init__()
        self.trunk = nn.Sequential(
            nn.Linear(feature_dim + action_dim, width), nn.LayerNorm(width), nn.ReLU()
        )
        self.mu = nn.Linear(width, feature_dim)
        self.sigma = nn.Linear(width, feature_dim)
        self.min_sigma, self.max_sigma = min_sigma, max_sigma

    def forward(self, z: th.Tensor, action: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """The predicted next encoding's mean and std."""
        x = self.trunk(th.cat([z, action], dim=1))
        span = self.max_sigma - self.min_sigma
        return self.mu(x), self.min_sigma + span * th.sigmoid(self.sigma(x))


def reward_decoder(feature_dim: int, width: int = 512) -> nn.Sequential:
    """R̂(z'): ``Linear → LayerNorm → ReLU → Linear`` to one reward (the authors' decoder)."""
    return nn.Sequential(
        nn.Linear(feature_dim, width), nn.LayerNorm(width), nn.ReLU(), nn.Linear(width, 1)
    )


def _orthogonal(module: nn.Module) -> None:
    """The authors' initialisation of actor, critic and encoder: orthogonal weights, zero bias."""
    if isinstance(module, nn.Linear):
        nn.init.orthogonal_(module.weight)
        nn.init.zeros_(module.bias)


class DBCActor(Actor):
    """SB3's SAC actor on the detached encoding, its log std rescaled into the authors' bounds."""

    def __init__(self, *args: Any, log_std_bounds: tuple[float, float], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.log_std_bounds = (float(log_std_bounds[0]), float(log_std_bounds[1]))
        """``(min, max)`` of the log std (the authors' ``actor_log_std_min/max``)."""

    def extract_features(self, obs: Any, features_extractor: BaseFeaturesExtractor) -> th.Tensor:
        """The shared encoder's output, detached: the actor's loss never trains the encoder."""
        return super().extract_features(obs, features_extractor).detach()

    def get_action_dist_params(self, obs: Any) -> tuple[th.Tensor, th.Tensor, dict]:
        """Mean and log std, the log std ``lo + (hi − lo)·(tanh(x) + 1)/2`` as the authors'."""
        latent = self.latent_pi(self.extract_features(obs, self.features_extractor))
        low, high = self.log_std_bounds
        log_std = low + 0.5 * (high - low) * (th.tanh(self.log_std(latent)) + 1)  # type: ignore[operator]
        return self.mu(latent), log_std, {}


class DBCPolicy(SACPolicy):
    """`SACPolicy` with DBC's encoder, transition model and reward decoder (see the module).

    Defaults: the Robust Gymnasium paper's DBC parameters and the authors' code.

    Args beyond `SACPolicy`'s:
        feature_dim: size of the encoding (paper: encoder feature dim 256).
        encoder_arch: the encoder's hidden ReLU layers before its ``Linear → LayerNorm``.
        model_width: hidden width of the transition model and the reward decoder (authors: 512).
        encoder_lr: the encoder's Adam rate in the model step (paper: 1e-4).
        decoder_lr: the transition model's and reward decoder's Adam rate (paper: 1e-4).
        log_std_min, log_std_max: the actor's log std bounds (paper: -10 and 2).
    """

    actor: DBCActor

    def __init__(
        self,
        *args: Any,
        feature_dim: int = 256,
        encoder_arch: Any = (256,),
        model_width: int = 512,
        encoder_lr: float = 1e-4,
        decoder_lr: float = 1e-4,
        log_std_min: float = -10.0,
        log_std_max: float = 2.0,
        **kwargs: Any,
    ) -> None:
        if kwargs.get("use_sde"):
            raise ValueError("DBCPolicy does not support gSDE (use_sde=True).")
        self.feature_dim, self.encoder_arch = int(feature_dim), [int(w) for w in encoder_arch]
        self.model_width, self.encoder_lr, self.decoder_lr = model_width, encoder_lr, decoder_lr
        self.log_std_min, self.log_std_max = log_std_min, log_std_max
        kwargs.setdefault("net_arch", [256, 256, 256])
        kwargs["features_extractor_class"] = BisimEncoder
        kwargs["features_extractor_kwargs"] = {
            "feature_dim": self.feature_dim, "hidden": self.encoder_arch,
        }  # fmt: skip
        super().__init__(*args, **kwargs)

    def _build(self, lr_schedule: Any) -> None:
        self.critic = self.make_critic(features_extractor=None)  # owns the encoder
        self.actor = self.make_actor(features_extractor=self.critic.features_extractor)
        self.critic.apply(_orthogonal)
        for name, module in self.actor.named_children():
            if name != "features_extractor":
                module.apply(_orthogonal)
        own = [p for n, p in self.actor.named_parameters() if not n.startswith("features_")]
        rate, make = lr_schedule(1), self.optimizer_class  # SB3's Optimizer type lacks `lr`
        self.actor.optimizer = make(own, lr=rate, **self.optimizer_kwargs)  # type: ignore[call-arg]
        critic = list(self.critic.parameters())  # the encoder's weights among them
        self.critic.optimizer = make(critic, lr=rate, **self.optimizer_kwargs)  # type: ignore[call-arg]
        self.critic_target = self.make_critic(features_extractor=None)  # the target encoder too
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.critic_target.set_training_mode(False)
        action_dim = int(self.action_space.shape[0])  # type: ignore[index]
        self.transition_model = GaussianTransition(self.feature_dim, action_dim, self.model_width)
        self.reward_decoder = reward_decoder(self.feature_dim, self.model_width)
        self.encoder_optimizer = th.optim.Adam(
            self.encoder.parameters(), lr=self.encoder_lr, fused=True
        )
        decoders = [*self.transition_model.parameters(), *self.reward_decoder.parameters()]
        self.decoder_optimizer = th.optim.Adam(decoders, lr=self.decoder_lr, fused=True)

    @property
    def encoder(self) -> BisimEncoder:
        """φ: the critic's features extractor, which the actor reads detached."""
        return self.critic.features_extractor  # type: ignore[return-value]

    @property
    def target_encoder(self) -> BisimEncoder:
        """φ̄: the target critic's features extractor."""
        return self.critic_target.features_extractor  # type: ignore[return-value]

    def encode(self, obs: Any) -> th.Tensor:
        """φ(obs) with SB3's preprocessing (a float64 replay batch becomes float32)."""
        return self.critic.extract_features(obs, self.encoder)

    def make_actor(self, features_extractor: Any = None) -> DBCActor:
        """The actor, reading `features_extractor` (the critic's encoder) detached."""
        kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        bounds = (self.log_std_min, self.log_std_max)
        return DBCActor(**kwargs, log_std_bounds=bounds).to(self.device)

    def set_training_mode(self, mode: bool) -> None:
        """Training or evaluation mode for every network (the target critic stays in eval)."""
        super().set_training_mode(mode)
        self.transition_model.train(mode)
        self.reward_decoder.train(mode)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            feature_dim=self.feature_dim, encoder_arch=self.encoder_arch,
            model_width=self.model_width, encoder_lr=self.encoder_lr,
            decoder_lr=self.decoder_lr, log_std_min=self.log_std_min,
            log_std_max=self.log_std_max,
        )  # fmt: skip
        data.pop("features_extractor_class", None)
        data.pop("features_extractor_kwargs", None)
        return data
