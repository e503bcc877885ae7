"""OMPO's networks as a Stable-Baselines3 SAC policy: a LayerNorm + tanh layer, then ELU layers.

OMPO's authors build every network (actor, both critics, the value net they do not use) as
``Linear -> LayerNorm -> tanh -> Linear -> ELU -> head`` with Xavier-uniform weights and zero
biases. `OMPOPolicy` is SB3's `SACPolicy` with those trunks in place of its ReLU MLPs, so the
SAC machinery (squashed Gaussian, ``log_std`` clamped to [-20, 2], twin critics, save/load)
stays SB3's. The same policy also serves the SAC it is compared with in the speed benchmark.

Two choices are for speed alone, both measured by ``benchmarks/bench_ompo.py`` (docs/ompo.md):
the tanh is `SigmoidTanh` (``2σ(2x) − 1``, the same function: PyTorch's CPU tanh is some six
times slower than its sigmoid on these 256-wide batches), and Adam is PyTorch's fused kernel.
"""

from __future__ import annotations

from typing import Any

import torch
from stable_baselines3.common.policies import ContinuousCritic
from stable_baselines3.sac.policies import Actor, SACPolicy
from torch import nn

__all__ = ["OMPOPolicy", "SigmoidTanh", "trunk"]


class _SigmoidTanh(torch.autograd.Function):
    """tanh as ``2σ(2x) − 1``; its gradient ``g (1 − y²)`` from the output, as tanh's."""

    @staticmethod
    def forward(ctx: Any, x: torch.Tensor) -> torch.Tensor:
        y = torch.sigmoid(x * 2).mul_(2).sub_(1)
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> torch.Tensor:
        (y,) = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, y)


class SigmoidTanh(nn.Module):
    """The hyperbolic tangent computed as ``2σ(2x) − 1`` (within 2e-7 of `torch.tanh`).

    On one CPU thread PyTorch's tanh of a 512 × 256 batch takes about 360 µs and its sigmoid
    about 55 µs (27 Nov 2026, this machine), so the same function through the sigmoid is about
    1.7 times faster forward and backward on OMPO's batches; on small ones (64 × 64) it is slower.
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``tanh(x)``."""
        return _SigmoidTanh.apply(x)


def trunk(inputs: int, hidden: list[int]) -> list[nn.Module]:
    """OMPO's hidden layers: the first normalised and squashed (LayerNorm, tanh), the rest ELU."""
    layers: list[nn.Module] = []
    last = inputs
    for i, width in enumerate(hidden):
        layers.append(nn.Linear(last, width))
        layers += [nn.LayerNorm(width), SigmoidTanh()] if i == 0 else [nn.ELU()]
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
    """`SACPolicy` whose actor and critics use OMPO's networks (hidden [256, 256] by default).

    Their Adam is fused (unless ``optimizer_kwargs`` says ``"fused": False``): no NumPy copy
    reads these networks while they train (`advgame.agents.sb3.config` explains the choice).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("net_arch", [256, 256])
        options = dict(kwargs.get("optimizer_kwargs") or {})
        if options.get("fused") is not False:  # fused, in place of advgame's default foreach
            options.pop("foreach", None)
            options["fused"] = True
        kwargs["optimizer_kwargs"] = options
        super().__init__(*args, **kwargs)

    def make_actor(self, features_extractor: Any = None) -> Actor:
        """The actor, with OMPO's trunk."""
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return OMPOActor(**actor_kwargs).to(self.device)

    def make_critic(self, features_extractor: Any = None) -> ContinuousCritic:
        """The twin critic, with OMPO's trunks."""
        critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)
        return OMPOCritic(**critic_kwargs).to(self.device)
