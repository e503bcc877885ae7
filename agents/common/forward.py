"""A batch-invariant actor forward pass for SB3 policies (what frozen opponents run each step).

Torch's CPU matrix product picks its kernel by batch size, so row ``i`` of a batched forward
pass may differ from a one-row forward pass of the same input in the last bit; on a chaotic
simulator that is enough for a batched episode to drift from the same episode played alone.
`ActorForward` computes an ``nn.Linear`` as a batch of one-row products (``baddbmm`` with
the bias broadcast) where a probe shows that this reproduces the one-row product, and row by
row where it does not (narrow layers, which torch computes as matrix-vector products), so row
``i`` is exactly what SB3's ``predict`` gives for observation ``i`` alone (checked in
``tests/test_vector.py`` for PPO, SAC and TD3). It also skips SB3's
distribution objects, so one call is cheaper than ``policy._predict`` even for one row.

Only plain actors are covered: a flatten feature extractor, MLP layers of ``nn.Linear`` and
element-wise activations, and a deterministic Gaussian (its mean), squashed Gaussian (tanh of
its mean) or categorical (argmax) head. Anything else returns ``None`` and the caller falls
back to SB3's own ``_predict``, one row at a time.
"""

from __future__ import annotations

import weakref
from typing import Any

__all__ = ["ActorForward", "actor_head"]

_ELEMENTWISE = ("Tanh", "ReLU", "ELU", "LeakyReLU", "Sigmoid", "SiLU", "GELU", "Identity")
_PROBE_SIZES = (2, 3, 5, 8, 16, 33)
_CACHE: weakref.WeakKeyDictionary[Any, ActorForward | None] = weakref.WeakKeyDictionary()


class _Unsupported(Exception):
    """A layer this forward pass does not reproduce exactly."""


def _operands(weight: Any, bias: Any, n: int) -> tuple[Any, Any]:
    """A linear layer's weight and bias as ``[n, ...]`` views for `_batched_linear`."""
    return weight.T.expand(n, -1, -1), None if bias is None else bias.expand(n, 1, -1)


def _batched_linear(weight: Any, bias: Any, x: Any) -> Any:
    """``x @ W.T + b`` as a batch of one-row products, with `_operands`' views."""
    import torch

    if bias is None:
        return torch.bmm(x[:, None, :], weight)[:, 0]
    return torch.baddbmm(bias, x[:, None, :], weight)[:, 0]


def _reproduces(module: Any) -> bool:
    """Whether `_batched_linear` gives, row for row, what `module` gives one row at a time.

    Torch picks the kernel of a one-row product by shape (a matrix-vector product for narrow
    outputs), so this is probed once per layer on random inputs at several batch sizes.
    """
    import torch

    gen = torch.Generator().manual_seed(0)
    for n in _PROBE_SIZES:
        x = torch.randn(n, module.in_features, generator=gen)
        rows = torch.cat([module(x[i : i + 1]) for i in range(n)])
        batched = _batched_linear(*_operands(module.weight, module.bias, n), x)
        if not torch.equal(batched, rows):
            return False
    return True


class ActorForward:
    """The deterministic actor of one SB3 policy, batch-invariant (see the module docstring).

    Build it with `ActorForward.of` (None for an actor it does not cover); call it on a float32
    batch ``[n, obs]``. One row runs each layer as the function its ``forward`` calls; more rows
    run each linear layer as one batched product where that reproduces the one-row result
    (probed per layer), else row by row.
    """

    def __init__(self, layers: list[Any], kind: str) -> None:
        import torch

        self.layers, self.kind = layers, kind
        # per layer: how `__call__` runs it, the layer, its own parameter dict (it sees new
        # weights), and for a linear layer whether one batched product reproduces its rows
        self._ops: list[tuple[str, Any, Any, bool]] = []
        with torch.no_grad():
            for layer in self._modules()[1:]:  # the flatten extractor is `__call__`'s flatten
                op = _op(layer)
                self._ops.append(
                    (op, layer, layer._parameters, op == "linear" and _reproduces(layer))
                )
        self._expanded: dict[tuple[int, int], tuple[Any, Any, Any, Any]] = {}

    @classmethod
    def of(cls, policy: Any) -> ActorForward | None:
        """The forward pass of `policy`'s actor, or None if its layers are not covered.

        Cached per policy module (the probes run once per loaded network, not per build).
        """
        if policy in _CACHE:
            return _CACHE[policy]
        head = actor_head(policy)
        try:
            out = None if head is None else cls(*head)
        except _Unsupported:
            out = None
        _CACHE[policy] = out
        return out

    def _modules(self) -> list[Any]:
        out: list[Any] = []
        for module in self.layers:
            layers = list(module) if type(module).__name__ == "Sequential" else [module]
            for layer in layers:
                name = type(layer).__name__
                if name not in ("Linear", "Flatten", "FlattenExtractor", *_ELEMENTWISE):
                    raise _Unsupported(name)
                out.append(layer)
        return out

    def _linear_rows(self, layer: Any, weight: Any, bias: Any, x: Any) -> Any:
        """`_batched_linear` of `layer`, with its `_operands` kept per batch size.

        They are views, not copies: they follow the parameters' in-place updates, and a new
        parameter object (a layer given new weights) builds them again.
        """
        n = x.shape[0]
        key = (id(layer), n)
        cached = self._expanded.get(key)
        if cached is None or cached[0] is not weight or cached[1] is not bias:
            cached = self._expanded[key] = (weight, bias, *_operands(weight, bias, n))
        return _batched_linear(cached[2], cached[3], x)

    def __call__(self, obs: Any) -> Any:
        """Deterministic actions for the batch `obs` (before SB3's clipping or unscaling).

        Layers run as the functions their ``forward`` calls (``F.linear`` with the layer's
        own parameters, ``torch.tanh``, ``torch.relu``): the same kernels on the same tensors,
        so the same bits, without ``nn.Module.__call__``'s hook machinery, which costs as much
        as the arithmetic for these small networks.
        """
        import torch
        from torch.nn import functional

        x = obs if obs.ndim == 2 else obs.flatten(1)  # the flatten feature extractor
        n = x.shape[0]
        with torch.no_grad():
            for op, layer, params, batches in self._ops:
                if op == "linear":
                    w, b = params["weight"], params["bias"]
                    if n <= 1:  # one row
                        x = functional.linear(x, w, b)
                    elif batches:
                        x = self._linear_rows(layer, w, b, x)
                    else:
                        x = torch.cat([functional.linear(x[i : i + 1], w, b) for i in range(n)])
                elif op == "tanh":
                    x = torch.tanh(x)
                elif op == "relu":
                    x = torch.relu(x)
                elif op == "module":
                    x = layer(x)
        if self.kind == "tanh":
            return torch.tanh(x)
        if self.kind == "argmax":
            return torch.argmax(x, dim=1)
        return x


def _op(layer: Any) -> str:
    """How `ActorForward.__call__` runs `layer`: as the function its ``forward`` calls."""
    name = type(layer).__name__
    if name == "Linear":
        return "linear"
    if name == "Tanh":
        return "tanh"
    if name == "ReLU" and not layer.inplace:
        return "relu"
    return "identity" if name == "Identity" else "module"


def actor_head(policy: Any) -> tuple[list[Any], str] | None:
    """The layers `ActorForward` runs for an SB3 `policy` and its head kind, or None.

    Kinds: ``"mean"`` (PPO Gaussian, TD3), ``"tanh"`` (SAC's squashed Gaussian), ``"argmax"``
    (PPO categorical).
    """
    dist = type(getattr(policy, "action_dist", None)).__name__
    if hasattr(policy, "mlp_extractor"):  # PPO / A2C ActorCriticPolicy
        kind = {"DiagGaussianDistribution": "mean", "CategoricalDistribution": "argmax"}.get(dist)
        if kind is None or getattr(policy, "use_sde", False):
            return None
        extractor = getattr(policy, "pi_features_extractor", policy.features_extractor)
        return [extractor, policy.mlp_extractor.policy_net, policy.action_net], kind
    actor = getattr(policy, "actor", None)
    if actor is None or getattr(actor, "use_sde", False):
        return None
    if hasattr(actor, "latent_pi"):  # SAC: squashed Gaussian, deterministic = tanh(mean)
        if type(actor.action_dist).__name__ != "SquashedDiagGaussianDistribution":
            return None
        return [actor.features_extractor, actor.latent_pi, actor.mu], "tanh"
    return [actor.features_extractor, actor.mu], "mean"  # TD3: mu ends in its own tanh
