"""A frozen feed-forward network in NumPy, with the gradient of its output in its input.

White-box attacks (`advgame.adversaries.whitebox`) take about ten gradient steps through the
protagonist's small MLP at every attacked step. Through torch each step is a graph, an autograd
pass and a dozen module calls: for a 64-unit network and a lockstep group of games, that
bookkeeping costs several times the arithmetic. `NumpyNet` is the same network as plain NumPy:
`forward` keeps what the backward pass needs, `backward` returns the vector-Jacobian product
in the input.

It covers what SB3's default policies are made of: the observation normalizer (shift, scale,
clip, as `VecNormalize` applies it), ``nn.Linear``, ``nn.Tanh`` and ``nn.ReLU``, in float32;
and, first after the normalizer, one step of a one-layer ``nn.LSTM`` at a frozen memory
(`advgame.core.numpy_lstm.LSTMCell`, sb3-contrib's recurrent policies; `NumpyNet.at_memory`).
Every linear layer runs as a stack of one-row products (``[n, 1, in] @ W``), the shape a lone
row has, so row ``i`` of a batch is computed exactly as that row alone: a lockstep group of
attacked games walks as each game would alone. `NumpyNet.of` probes that once per network
(forward and backward at several batch sizes) and returns None where this NumPy build does
not reproduce lone rows, or where a layer is not covered; the caller then keeps torch.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import numpy as np

from advgame.core.numpy_lstm import LSTMCell
from advgame.core.policy import plain_gaussian

__all__ = ["NetCache", "NumpyNet", "sb3_modules", "weights_stamp"]

_PROBE_SIZES = (2, 3, 8, 33)


class NumpyNet:
    """A frozen copy of a Linear/Tanh/ReLU stack (maybe an LSTM step first), behind a normalizer.

    Build it with `NumpyNet.of`. ``forward(x)`` for a float32 batch ``[n, in]`` returns the
    output ``[n, out]`` and a tape; ``backward(tape, g)`` returns ``g``'s vector-Jacobian
    product in ``x`` (``[n, in]``): the gradient of ``(output * g).sum()``.

    Args:
        layers: ``("linear", W [in, out], b [out])``, ``("tanh",)``, ``("relu",)`` or
            ``("lstm", LSTMCell)`` (the first layer only), in order.
        normalizer: ``(mean, std, clip)``: the input becomes ``clip((x - mean) / std)`` first
            (float32, as advgame's policies normalize for the network), or None.

    """

    def __init__(
        self,
        layers: Sequence[tuple[Any, ...]],
        normalizer: tuple[np.ndarray, np.ndarray, float] | None = None,
    ) -> None:
        self._layers: list[tuple[str, Any, Any, Any]]  # kind, W [in, out], b, W.T
        self._layers = []
        for layer in layers:
            if layer[0] == "linear":
                w = np.ascontiguousarray(layer[1], dtype=np.float32)
                b = np.asarray(layer[2], dtype=np.float32)
                self._layers.append(("linear", w, b, np.ascontiguousarray(w.T)))
            elif layer[0] in ("tanh", "relu"):
                self._layers.append((layer[0], None, None, None))
            elif layer[0] == "lstm" and not self._layers:
                self._layers.append(("lstm", layer[1], None, None))
            else:
                raise ValueError(
                    f"NumpyNet covers linear, tanh and relu layers and a first lstm layer, not "
                    f"{layer[0]!r} at position {len(self._layers)}."
                )
        self._norm = _float32_normalizer(normalizer)

    def behind(self, normalizer: tuple[np.ndarray, np.ndarray, float] | None) -> NumpyNet:
        """The same layers (shared, not copied) behind another input `normalizer`.

        The normalizer is element-wise, so a batched row is still the row alone: no new probe.
        """
        net = copy.copy(self)
        net._norm = _float32_normalizer(normalizer)
        return net

    def at_memory(self, h: np.ndarray, c: np.ndarray) -> NumpyNet:
        """The same net (weights shared) with its LSTM step at memory ``h, c`` (each ``[H]``).

        The memory enters element-wise (a bias and ``c``), so a batched row is still the row
        alone: no new probe. Raises ValueError for a net without an LSTM step.
        """
        kind, cell, _, _ = self._layers[0]
        if kind != "lstm":
            raise ValueError("at_memory needs a NumpyNet that starts with an LSTM step.")
        net = copy.copy(self)
        net._layers = [("lstm", cell.at(h, c), None, None), *self._layers[1:]]
        return net

    @classmethod
    def of(
        cls,
        modules: Sequence[Any],
        normalizer: tuple[np.ndarray, np.ndarray, float] | None = None,
        probe: bool = True,
    ) -> NumpyNet | None:
        """The NumPy copy of torch `modules` (layers and ``nn.Sequential`` blocks, in order), or None.

        None when a module is not ``nn.Linear``, ``nn.Tanh``, ``nn.ReLU``, ``nn.Flatten`` or a
        first one-layer ``nn.LSTM`` (copied at the zero memory: `at_memory` moves it), or
        when the probe finds a batched row differs from the same row alone in any bit
        (``probe=False`` skips it: for a copy whose rows need not match lone rows, such as a
        learner's minibatch).
        """
        layers: list[tuple[Any, ...]] = []
        for module in modules:
            children = list(module) if type(module).__name__ == "Sequential" else [module]
            for layer in children:
                name = type(layer).__name__
                if name == "Linear":
                    bias = layer.bias
                    b = np.zeros(layer.out_features) if bias is None else bias.detach().numpy()
                    layers.append(("linear", layer.weight.detach().numpy().T, b))
                elif name in ("Tanh", "ReLU"):
                    layers.append((name.lower(),))
                elif name == "LSTM" and not layers and (cell := LSTMCell.of(layer)) is not None:
                    layers.append(("lstm", cell))
                elif name not in ("Flatten", "Identity"):
                    return None
        if not layers or layers[0][0] not in ("linear", "lstm"):
            return None
        net = cls(layers, normalizer)
        return net if not probe or net._probe() else None

    @property
    def in_features(self) -> int:
        """The width of the input."""
        kind, first, _, _ = self._layers[0]
        assert first is not None  # `of` and the constructor start with a linear or lstm layer
        return int(first.in_features if kind == "lstm" else first.shape[0])

    def forward(self, x: np.ndarray) -> tuple[np.ndarray, list[Any]]:
        """The output ``[n, out]`` for a float32 batch ``[n, in]``, and the tape for `backward`."""
        tape: list[Any] = []
        h = np.asarray(x, dtype=np.float32)
        if self._norm is not None:
            mean, std, clip = self._norm
            z = (h - mean) / std
            tape.append((z >= -clip) & (z <= clip))  # where the clip passes the gradient
            h = z.clip(-clip, clip)
        h = h[:, None, :]
        for kind, w, b, _ in self._layers:
            if kind == "linear":
                h = np.matmul(h, w) + b
            elif kind == "lstm":
                h, saved = w.forward(h)
                tape.append(saved)
            elif kind == "tanh":
                h = np.tanh(h)
                tape.append(h)
            else:
                tape.append(h > 0)
                h = np.maximum(h, np.float32(0))
        return h[:, 0, :], tape

    def backward(self, tape: list[Any], grad: np.ndarray) -> np.ndarray:
        """The gradient in the input of ``(output * grad).sum()`` (`forward`'s `tape`)."""
        g = np.asarray(grad, dtype=np.float32)[:, None, :]
        saved = len(tape)
        for kind, w, _, wt in reversed(self._layers):
            if kind == "linear":
                g = np.matmul(g, wt)
            elif kind == "lstm":
                saved -= 1
                g = w.backward(tape[saved], g)
            elif kind == "tanh":
                saved -= 1
                y = tape[saved]
                g = g * (np.float32(1) - y * y)
            else:
                saved -= 1
                g = g * tape[saved]
        g = g[:, 0, :]
        if self._norm is not None:
            g = g * tape[0] / self._norm[1]
        return g

    def _probe(self) -> bool:
        """Whether forward and backward give every row of a batch exactly as that row alone."""
        rng = np.random.default_rng(0)
        for n in _PROBE_SIZES:
            x = rng.normal(size=(n, self.in_features)).astype(np.float32)
            out, tape = self.forward(x)
            g_out = rng.normal(size=out.shape).astype(np.float32)
            g_in = self.backward(tape, g_out)
            for i in range(n):
                lone, lone_tape = self.forward(x[i : i + 1])
                lone_in = self.backward(lone_tape, g_out[i : i + 1])
                if not (np.array_equal(lone[0], out[i]) and np.array_equal(lone_in[0], g_in[i])):
                    return False
        return True


def _float32_normalizer(
    normalizer: tuple[np.ndarray, np.ndarray, float] | None,
) -> tuple[np.ndarray, np.ndarray, np.float32] | None:
    if normalizer is None:
        return None
    mean, std, clip = normalizer
    mean32 = np.asarray(mean, dtype=np.float32).reshape(-1)
    return mean32, np.asarray(std, dtype=np.float32).reshape(-1), np.float32(clip)


def sb3_modules(policy: Any, head: str) -> list[Any] | None:
    """The torch modules from an SB3 policy's input features to its `head`, or None.

    ``"mean"``: the Gaussian mean of a plain ``ActorCriticPolicy`` (PPO, A2C: a flatten
    extractor, SB3's ``MlpExtractor``, a diagonal Gaussian); ``"value"``: its value head. None
    for anything else (SAC, TD3, a custom extractor or distribution): attacks keep torch.
    """
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.torch_layers import FlattenExtractor, MlpExtractor

    if not isinstance(policy, ActorCriticPolicy) or type(policy.mlp_extractor) is not MlpExtractor:
        return None
    kind = type(policy)
    if head == "mean":
        plain = plain_gaussian(policy)
        extractor = policy.pi_features_extractor
        layers = [policy.mlp_extractor.policy_net, policy.action_net]
    elif head == "value":
        plain = kind.predict_values is ActorCriticPolicy.predict_values
        extractor = policy.vf_features_extractor
        layers = [policy.mlp_extractor.value_net, policy.value_net]
    else:
        raise ValueError(f"head must be 'mean' or 'value', got {head!r}.")
    if not plain or type(extractor) is not FlattenExtractor:
        return None
    return layers


def weights_stamp(modules: Sequence[Any]) -> tuple[Any, ...]:
    """What changes when any parameter of `modules` is replaced or updated in place.

    A `NumpyNet` is a copy: its owner rebuilds it when the stamp of the torch modules it
    copied changes (a live learner between updates). Torch counts in-place updates of a tensor
    (``_version``); where a build lacks that counter, the stamp is the parameters' bytes.
    """
    stamp = []
    for module in modules:
        for p in module.parameters():
            version = getattr(p, "_version", None)
            stamp.append((id(p), p.detach().numpy().tobytes() if version is None else version))
    return tuple(stamp)


class NetCache:
    """The `NumpyNet` copies of a torch policy's heads, rebuilt when weights or normalizer change.

    Example:
        >>> from torch import nn
        >>> cache, net = NetCache(), nn.Sequential(nn.Linear(3, 4), nn.Tanh(), nn.Linear(4, 2))
        >>> cache.get("mean", [net], None).forward(np.zeros((5, 3), np.float32))[0].shape
        (5, 2)

    """

    def __init__(self) -> None:
        # per head: (weights stamp, the probed layers, normalizer bytes, the net behind them)
        self._nets: dict[str, tuple[Any, NumpyNet | None, Any, NumpyNet | None]] = {}

    def get(
        self,
        head: str,
        modules: Sequence[Any] | None,
        normalizer: tuple[np.ndarray, np.ndarray, float] | None,
    ) -> NumpyNet | None:
        """The copy of `modules` behind `normalizer` (None if `modules` is None or not covered)."""
        if modules is None:
            return None
        stamp = weights_stamp(modules)
        hit = self._nets.get(head)
        if hit is None or hit[0] != stamp:  # new weights: copy and probe them again
            base = NumpyNet.of(modules)
            hit = self._nets[head] = (stamp, base, None, base)
        norm = None if normalizer is None else tuple(np.asarray(v).tobytes() for v in normalizer)
        if hit[1] is not None and norm != hit[2]:  # new statistics: the same layers behind them
            hit = self._nets[head] = (stamp, hit[1], norm, hit[1].behind(normalizer))
        return hit[3]
