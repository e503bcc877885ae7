"""The one interface every policy shares: protagonists, noise, schedules, networks, LLMs.

A `Policy` is stateful within an episode: `reset` starts an episode (with a seed), `act` maps
one observation to one action. A `PolicySpec` is a small picklable config that *builds* a
policy for one agent of one game, given that agent's `AgentInfo` (its spaces and, for an
adversary, its disruptor, whose `encode` turns raw perturbations into actions). Specs are what
presets, populations and worker processes pass around.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from gymnasium import spaces

from advgame.errors import ConfigError

if TYPE_CHECKING:
    from advgame.core.disruptor import Disruptor

__all__ = [
    "AgentInfo",
    "CallablePolicy",
    "ConstantPolicy",
    "Policy",
    "PolicySpec",
    "WhiteBox",
    "WhiteBoxForwarder",
    "act_batch",
    "as_policy",
    "gaussian_mean",
]


@runtime_checkable
class Policy(Protocol):
    """Chooses actions for one agent."""

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode; `seed` reseeds any randomness."""

    def act(self, observation: Any) -> Any:
        """The action for `observation`."""


# A policy may also offer ``act_batch(observations[n, ...]) -> actions[n, ...]`` with a
# ``batch_key`` property: policies with equal non-None keys (e.g. N views' copies of one frozen
# network) are then served by one `act_batch` call (see `act_batch` below). Both are optional.
# A policy whose batched pass cannot reproduce its one-row pass (an LSTM: torch's oneDNN kernel
# rounds a row of a batch differently) keeps ``batch_key`` None and may offer
# ``inexact_batch_key`` with ``act_group``: callers that accept last-bit differences from play
# alone (training rollouts, `act_batch(..., exact=False)`) then ask its copies at once.
# A policy that follows a per-episode schedule (a sinusoidal shift) may offer
# ``set_episode_index(index)``: its next `reset` then starts episode `index` of its schedule
# instead of the next of its own count (evaluation tables declare which episode each of their
# episodes plays; `advgame.core.episodes.reseed_policies`). Optional too. Such a policy may
# also offer ``episode_index()``: the index of the episode it plays now, which a training
# checkpoint saves so that a resumed run goes on with the next one (`advgame.core.views`).


@runtime_checkable
class PolicySpec(Protocol):
    """A picklable recipe that builds a `Policy` for one agent."""

    def build(self, info: AgentInfo) -> Policy:
        """Build the policy for the agent described by `info`."""


@runtime_checkable
class WhiteBox(Protocol):
    """A protagonist policy whose networks a white-box attack may differentiate (never train).

    Every method takes a batch of *raw* observations as a float32 torch tensor ``[batch, obs]``
    and applies the policy's own frozen normalizer, so an attack works in the units the game
    uses. Implemented by `advgame.agents.common.sb3_policy.SB3Policy` (and its recurrent subclass) and the MAPPO/IPPO actor policies.

    Optionally a policy also has ``numpy_net(head)``: ``"mean"`` (`action_mean`) or ``"value"``
    (`value`, for a policy without a Q critic) as an `advgame.core.numpy_net.NumpyNet`, the same
    function in NumPy with its input gradient, or None. White-box attacks walk through it where
    it is there (SB3's PPO, sb3-contrib's RecurrentPPO at its carried memory, saved MAPPO/IPPO
    actors) and through torch otherwise.
    """

    def action_mean(self, obs: Any) -> Any:
        """The action the policy would take (its distribution's mean), differentiable in `obs`."""

    def action_std(self) -> Any:
        """The standard deviation of a Gaussian policy's actions, or ``None`` (deterministic)."""

    def value(self, obs: Any) -> Any:
        """The state-value estimate ``V(obs)`` (``[batch]``), or ``None`` if the policy has none."""

    def q_value(self, obs: Any, action: Any) -> Any:
        """The action-value estimate ``Q(obs, action)`` (``[batch]``), or ``None``."""


class WhiteBoxForwarder:
    """Mixin for a wrapper of a `WhiteBox` policy: the four methods, forwarded to `wrapped`.

    Since Python 3.12, ``isinstance(x, WhiteBox)`` looks the methods up statically
    (`inspect.getattr_static`), so a wrapper whose ``__getattr__`` forwards to a white-box
    policy is not one. A wrapper class ``W`` with a ``wrapped`` property therefore has a
    white-box variant with this mixin last (``class _WhiteBoxW(W, WhiteBoxForwarder)``, so that
    ``W.wrapped`` wins), and whoever builds the wrapper picks that variant exactly when the
    policy it wraps is a `WhiteBox`: a wrapped black-box policy is still refused by white-box
    attacks with their clear error.
    """

    @property
    def wrapped(self) -> Any:
        """The white-box policy that answers (the wrapper defines it)."""
        raise NotImplementedError(f"{type(self).__name__} must define the `wrapped` property.")

    def action_mean(self, obs: Any) -> Any:
        """The wrapped policy's `WhiteBox.action_mean`."""
        return self.wrapped.action_mean(obs)

    def action_std(self) -> Any:
        """The wrapped policy's `WhiteBox.action_std`."""
        return self.wrapped.action_std()

    def value(self, obs: Any) -> Any:
        """The wrapped policy's `WhiteBox.value`."""
        return self.wrapped.value(obs)

    def q_value(self, obs: Any, action: Any) -> Any:
        """The wrapped policy's `WhiteBox.q_value`."""
        return self.wrapped.q_value(obs, action)

    def numpy_net(self, head: str) -> Any:
        """The wrapped policy's `numpy_net` (see `WhiteBox`), or None if it has none."""
        return numpy_net_of(self.wrapped, head)


@dataclass(frozen=True)
class AgentInfo:
    """What a policy needs to know about the agent it plays."""

    agent: str
    """The agent id."""
    observation_space: spaces.Space
    """What the agent observes."""
    action_space: spaces.Space
    """What the agent sends."""
    disruptor: Disruptor | None = None
    """The disruptor an adversary controls (``None`` for protagonists)."""

    def encode(self, value: Any) -> np.ndarray:
        """Raw perturbation (state offset, force, parameter value) -> this adversary's action."""
        if self.disruptor is None:
            raise ConfigError(
                f"{self.agent!r} is a protagonist; it has no disruptor to encode for."
            )
        return self.disruptor.encode(value)

    @property
    def action_shape(self) -> tuple[int, ...]:
        """Shape of the agent's actions (``()`` for a discrete choice)."""
        return tuple(self.action_space.shape or ())

    @property
    def action_size(self) -> int:
        """Number of action components."""
        return int(np.prod(self.action_shape))

    @property
    def noop_action(self) -> Any:
        """The identity action of an adversary (its disruptor leaves the task unchanged)."""
        if self.disruptor is None:
            raise ConfigError(f"{self.agent!r} is a protagonist; it has no no-op action.")
        return self.disruptor.noop_action


class ConstantPolicy:
    """Always the same action (e.g. an adversary's no-op)."""

    def __init__(self, action: Any) -> None:
        self.action = action

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset."""

    def act(self, observation: Any) -> Any:
        """The constant action."""
        return self.action


class CallablePolicy:
    """A plain function ``observation -> action`` as a policy (e.g. a fixed, trained controller)."""

    def __init__(self, fn: Callable[[Any], Any]) -> None:
        self.fn = fn

    def reset(self, seed: int | None = None) -> None:
        """Plain functions keep no episode state."""

    def act(self, observation: Any) -> Any:
        """Call the function."""
        return self.fn(observation)


def as_policy(obj: Any, info: AgentInfo) -> Policy:
    """Turn a `Policy`, a `PolicySpec` or a plain callable into a policy for `info.agent`."""
    if hasattr(obj, "build") and not hasattr(obj, "act"):
        return obj.build(info)
    if hasattr(obj, "act") and hasattr(obj, "reset"):
        return obj
    if callable(obj):
        return CallablePolicy(obj)
    raise ConfigError(
        f"Cannot use {obj!r} as the policy of {info.agent!r}: expected a Policy (reset/act), "
        "a PolicySpec (build) or a callable observation -> action."
    )


def act_batch(
    policies: Sequence[Any], observations: Sequence[Any], exact: bool = True
) -> Sequence[Any]:
    """``policies[i].act(observations[i])`` for every ``i``, in one call where the policies allow.

    Policies that expose an equal, non-None ``batch_key`` and an ``act_batch(obs[n, ...])``
    are served by one `act_batch` call of the first (e.g. N views of one frozen SB3 network);
    policies whose state differs per game (a white-box attack bound to its game) offer
    ``act_group(policies, obs[n, ...])`` instead; any other policy is asked one observation at
    a time. Every row is then exactly what the policy would answer alone.

    With ``exact=False`` policies that share an ``inexact_batch_key`` (the copies of one frozen
    LSTM, each with its own memory) are served by one ``act_group`` call too, whose rows may
    differ from play alone in the last bit: for training rollouts, never for evaluation.
    """
    if len(policies) == 1:
        return [policies[0].act(observations[0])]
    head = policies[0]
    key = getattr(head, "batch_key", None)
    if key is not None and all(getattr(p, "batch_key", None) == key for p in policies[1:]):
        if hasattr(head, "act_group"):  # policies with state per game (white-box attacks)
            return head.act_group(policies, np.array(observations))
        if hasattr(head, "act_batch"):
            return head.act_batch(np.array(observations))  # = np.stack for equal shapes
    if not exact:
        key = getattr(head, "inexact_batch_key", None)
        if key is not None and all(getattr(p, "inexact_batch_key", None) == key for p in policies):
            return head.act_group(policies, np.array(observations))
    return [p.act(o) for p, o in zip(policies, observations, strict=True)]


def plain_gaussian(policy: Any) -> bool:
    """Whether `policy` is SB3's own ``ActorCriticPolicy`` acting through a plain diagonal Gaussian.

    Its mean is then ``action_net(forward_actor(features(x)))``, which `gaussian_mean` and the
    NumPy copies of `advgame.core.numpy_net` compute without SB3's distribution objects.
    """
    from stable_baselines3.common.distributions import DiagGaussianDistribution
    from stable_baselines3.common.policies import ActorCriticPolicy

    kind = type(policy)
    return (
        isinstance(policy, ActorCriticPolicy)
        and kind.get_distribution is ActorCriticPolicy.get_distribution
        and kind._get_action_dist_from_latent is ActorCriticPolicy._get_action_dist_from_latent
        and type(policy.action_dist) is DiagGaussianDistribution
    )


def numpy_net_of(policy: Any, head: str) -> Any:
    """``policy.numpy_net(head)`` (the optional `WhiteBox` method), or None where it has none."""
    numpy_net = getattr(policy, "numpy_net", None)
    return None if numpy_net is None else numpy_net(head)


def gaussian_mean(policy: Any, x: Any) -> Any:
    """``policy.get_distribution(x).distribution.mean``, without building the distribution.

    For SB3's own ``ActorCriticPolicy`` with a plain diagonal Gaussian the mean is
    ``action_net(forward_actor(features(x)))``: the same operations, differentiable in `x`, at a
    fraction of the Python cost (white-box attacks take it about ten times per step). None for
    any other policy (one that overrides those steps, another distribution): ask
    ``get_distribution``.
    """
    from stable_baselines3.common.policies import ActorCriticPolicy

    if not plain_gaussian(policy):
        return None
    extract = super(ActorCriticPolicy, policy).extract_features
    features = extract(x, policy.pi_features_extractor)
    return policy.action_net(policy.mlp_extractor.forward_actor(features))
