"""OMPO's networks as a Stable-Baselines3 SAC policy: a LayerNorm + tanh layer, then ELU layers.

OMPO's authors build every network (actor, both critics, the value net they do not use) as
``Linear -> LayerNorm -> tanh -> Linear -> ELU -> head`` with Xavier-uniform weights and zero
biases. `OMPOPolicy` is SB3's `SACPolicy` with those trunks in place of its ReLU MLPs, so the
SAC machinery (squashed Gaussian, ``log_std`` clamped to [-20, 2], twin critics, save/load)
stays SB3's. The same policy also serves the SAC it is compared with in the speed benchmark.
"""

from __future__ import annotations

from typing import Any

from stable_baselines3.common.policies import ContinuousCritic
from stable_baselines3.sac.policies import Actor, SACPolicy
from torch import nn

__all__ = ["OMPOPolicy", "trunk"]


def trunk(inputs: int, hidden: list[int]) -> list[nn.Module]:
    """OMPO's hidden layers: the first normalised and squashed (LayerNorm, tanh), the rest ELU."""
    layers: list[nn.Module] = []
    last = inputs
    for i, width in enumerate(hidden):
        layers.append(nn.Linear(last, width))
        layers += [nn.LayerNorm(width), nn.Tanh()] if i == 0 else [nn.ELU()]
        last = width
    return layers


def _xavier(module: nn.Module) -> None:
    """OMPO's initialisation: Xavier-uniform weights (gain 1), zero biases."""
    if isinstance(module, nn.Linear):
        nn.init.xavier_uniform_(module.weight, gain=1.0)
        nn.init.constant_(module.bias, 0.0)


class OMPOActor(Actor):
    """SB3's SAC actor with OMPO's trunk (the mean and log-std heads are SB3's)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.latent_pi = nn.Sequential(*trunk(self.features_dim, list(self.net_arch)))
        self.apply(_xavier)


class OMPOCritic(ContinuousCritic):
    """SB3's twin Q critic with OMPO's trunk in each Q network."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        net_arch, features = list(kwargs["net_arch"]), int(kwargs["features_dim"])
        width = features + int(self.action_space.shape[0])  # type: ignore[index]
        self.q_networks = []
        for idx in range(self.n_critics):
            q_net = nn.Sequential(*trunk(width, net_arch), nn.Linear(net_arch[-1], 1))
            self.add_module(f"qf{idx}", q_net)
            self.q_networks.append(q_net)
        self.apply(_xavier)


class OMPOPolicy(SACPolicy):
    """`SACPolicy` whose actor and critics use OMPO's networks (hidden [256, 256] by default)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("net_arch", [256, 256])
        super().__init__(*args, **kwargs)

    def make_actor(self, features_extractor: Any = None) -> Actor:
        """The actor, with OMPO's trunk."""
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return OMPOActor(**actor_kwargs).to(self.device)

    def make_critic(self, features_extractor: Any = None) -> ContinuousCritic:
        """The twin critic, with OMPO's trunks."""
        critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)
        return OMPOCritic(**critic_kwargs).to(self.device)
