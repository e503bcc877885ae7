"""One frozen LSTM step in NumPy, a `NumpyNet` layer: what attacks on a recurrent policy walk.

A white-box attack on a recurrent victim (sb3-contrib's ``RecurrentPPO``) computes the
perturbation of step t with the memory ``(h, c)`` the victim carries at t: it reads that
memory and never advances it. One LSTM step at a frozen memory is then a fixed function of
the input ``x``, which `LSTMCell` computes (PyTorch's ``nn.LSTM``, gate order i, f, g, o)::

    z = x W_ihᵀ + (b_ih + b_hh + W_hh h)        # the bracket: a constant of the step
    i, f, g, o = σ(z_i), σ(z_f), tanh(z_g), σ(z_o)
    c' = f c + i g,   h' = o tanh(c')           # the output is h'

The weights are copied once (per weights stamp, by `advgame.core.numpy_net.NetCache`); each
step only computes its constant bias and takes its ``c`` (`LSTMCell.at`). As every
`NumpyNet` layer, it multiplies one row at a time (``[n, 1, in] @ W``), so row ``i`` of a
batch is that row alone, and the rest is element-wise.

`recurrent_modules` picks the torch modules of a ``RecurrentPPO`` policy's mean or value head
and the memory each reads.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

__all__ = ["LSTMCell", "recurrent_modules"]


def _sigmoid(z: np.ndarray) -> np.ndarray:
    """``1 / (1 + exp(-z))`` in float32, as torch computes it.

    So it saturates where torch's does: exactly 1 where ``exp(-z)`` vanishes against 1, and
    exactly 0 where it overflows to infinity (no warning): a gate torch closes passes exactly
    no gradient here either, which a walk's signed steps can tell from a tiny one.
    """
    with np.errstate(over="ignore"):
        return np.float32(1) / (np.float32(1) + np.exp(-z))


class LSTMCell:
    """One step of a one-layer LSTM at a frozen memory ``(h, c)``, in float32.

    Built at the zero memory; `at` gives the same (shared) weights at another memory.
    ``forward(x [n, 1, in])`` returns ``h' [n, 1, H]`` and what `backward` needs;
    ``backward(saved, g [n, 1, H])`` returns the vector-Jacobian product in ``x``.

    Args:
        w_ih: ``[4H, in]``, the input weights (PyTorch's ``weight_ih_l0``).
        w_hh: ``[4H, H]``, the recurrent weights (``weight_hh_l0``).
        bias: ``[4H]``, ``b_ih + b_hh``.

    """

    def __init__(self, w_ih: np.ndarray, w_hh: np.ndarray, bias: np.ndarray) -> None:
        w_ih = np.asarray(w_ih, dtype=np.float32)
        self.hidden = int(w_ih.shape[0]) // 4
        if w_ih.shape[0] != 4 * self.hidden or np.shape(w_hh) != (4 * self.hidden, self.hidden):
            raise ValueError(
                f"LSTMCell needs w_ih [4H, in] and w_hh [4H, H], got {w_ih.shape} and "
                f"{np.shape(w_hh)}."
            )
        self._w = np.ascontiguousarray(w_ih.T)  # [in, 4H]: the forward product
        self._wt = np.ascontiguousarray(w_ih)  # [4H, in]: the backward product
        self._w_hh_t = np.ascontiguousarray(np.asarray(w_hh, dtype=np.float32).T)  # [H, 4H]
        self._bias = np.asarray(bias, dtype=np.float32).reshape(-1)
        self._step_bias = self._bias  # b_ih + b_hh + W_hh h at the memory of this step
        self._c = np.zeros(self.hidden, dtype=np.float32)

    @classmethod
    def of(cls, lstm: Any) -> LSTMCell | None:
        """The copy of a torch ``nn.LSTM`` (at the zero memory), or None where not covered.

        Covered: one layer, one direction, no projection, sequence-first (sb3-contrib's).
        """
        if lstm.num_layers != 1 or lstm.bidirectional or lstm.batch_first or lstm.proj_size:
            return None
        w_ih = lstm.weight_ih_l0.detach().numpy()
        bias = np.zeros(w_ih.shape[0], dtype=np.float32)
        if lstm.bias:
            bias = lstm.bias_ih_l0.detach().numpy() + lstm.bias_hh_l0.detach().numpy()
        return cls(w_ih, lstm.weight_hh_l0.detach().numpy(), bias)

    @property
    def in_features(self) -> int:
        """The width of the input."""
        return int(self._w.shape[0])

    def at(self, h: np.ndarray, c: np.ndarray) -> LSTMCell:
        """The same weights (shared) at memory ``h, c`` (each ``[H]``): one ``[H] @ [H, 4H]``."""
        h32 = np.asarray(h, dtype=np.float32).reshape(self.hidden)
        cell = copy.copy(self)
        # NumPy's own loop, not BLAS: OpenBLAS runs an [H] @ [H, 4H] product (H >= 48) on a
        # second thread, whose wake-up once a step costs milliseconds beside busy cores
        cell._step_bias = self._bias + np.einsum("h,hk->k", h32, self._w_hh_t)
        cell._c = np.asarray(c, dtype=np.float32).reshape(self.hidden)
        return cell

    def forward(self, x: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """``h'`` for the rows of ``x [n, 1, in]``, and the gates and ``tanh(c')``."""
        gates, _, tanh_c = self._cell(np.matmul(x, self._w) + self._step_bias, self._c)
        return gates[..., 3 * self.hidden :] * tanh_c, (gates, tanh_c)

    def step(self, x: np.ndarray, h: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One step of every row from its own memory: ``(h', c')`` for ``x [n, in]``, ``h, c [n, H]``.

        What a batch of episodes that each carry their memory needs (no gradient). Each row is
        multiplied alone (``[n, 1, in] @ W``), as in `forward`.
        """
        h32 = np.asarray(h, dtype=np.float32)[:, None, :]
        z = np.matmul(np.asarray(x, dtype=np.float32)[:, None, :], self._w)
        z += np.matmul(h32, self._w_hh_t)
        z += self._bias
        gates, c_next, tanh_c = self._cell(z, np.asarray(c, dtype=np.float32)[:, None, :])
        return (gates[..., 3 * self.hidden :] * tanh_c)[:, 0, :], c_next[:, 0, :]

    def _cell(self, z: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The gates (i, f, g, o) from their pre-activations `z`, ``c' = f c + i g`` and ``tanh(c')``."""
        size = self.hidden
        gates = _sigmoid(z)
        gates[..., 2 * size : 3 * size] = np.tanh(z[..., 2 * size : 3 * size])
        i, f, g = (gates[..., k * size : (k + 1) * size] for k in range(3))
        c_next = f * c + i * g
        return gates, c_next, np.tanh(c_next)

    def backward(self, saved: tuple[np.ndarray, np.ndarray], grad: np.ndarray) -> np.ndarray:
        """The gradient in ``x`` of ``(h' * grad).sum()`` (`forward`'s `saved`), ``[n, 1, in]``."""
        gates, tanh_c = saved
        size, one = self.hidden, np.float32(1)
        i, f, g, o = (gates[..., k * size : (k + 1) * size] for k in range(4))
        d_c = grad * o * (one - tanh_c * tanh_c)
        d_z = np.empty_like(gates)
        d_z[..., :size] = d_c * g * i * (one - i)
        d_z[..., size : 2 * size] = d_c * self._c * f * (one - f)
        d_z[..., 2 * size : 3 * size] = d_c * i * (one - g * g)
        d_z[..., 3 * size :] = grad * tanh_c * o * (one - o)
        return np.matmul(d_z, self._wt)


def recurrent_modules(policy: Any, head: str) -> tuple[list[Any], str | None] | None:
    """The torch modules of a ``RecurrentPPO`` policy from its features to `head`, or None.

    Returns the modules (an ``nn.LSTM`` first where the head reads one) and the memory the
    head reads: ``"actor"`` (the actor's LSTM: the mean, and the value of a shared LSTM),
    ``"critic"`` (the critic's own LSTM, sb3-contrib's default) or None (a critic without an
    LSTM: a linear layer, no memory). ``"mean"`` needs a plain diagonal Gaussian; both heads
    need sb3-contrib's own forward passes, ``MlpExtractor`` and a flatten feature extractor.
    None otherwise: attacks then keep torch.
    """
    from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy
    from stable_baselines3.common.distributions import DiagGaussianDistribution
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.torch_layers import FlattenExtractor, MlpExtractor

    if head not in ("mean", "value"):
        raise ValueError(f"head must be 'mean' or 'value', got {head!r}.")
    base, kind = RecurrentActorCriticPolicy, type(policy)
    if not isinstance(policy, base) or type(policy.mlp_extractor) is not MlpExtractor:
        return None
    mlp = policy.mlp_extractor
    if head == "mean":
        plain = (
            kind.get_distribution is base.get_distribution
            and kind._get_action_dist_from_latent is ActorCriticPolicy._get_action_dist_from_latent
            and type(policy.action_dist) is DiagGaussianDistribution
        )
        picked: tuple[list[Any], str | None] = [policy.lstm_actor], "actor"
        extractor = policy.pi_features_extractor
        tail = [mlp.policy_net, policy.action_net]
    else:
        plain = kind.predict_values is base.predict_values
        extractor, tail = policy.vf_features_extractor, [mlp.value_net, policy.value_net]
        if policy.lstm_critic is not None:
            picked = [policy.lstm_critic], "critic"
        elif policy.shared_lstm:
            picked = [policy.lstm_actor], "actor"
        else:
            picked = [policy.critic], None
    if not plain or type(extractor) is not FlattenExtractor:
        return None
    return [*picked[0], *tail], picked[1]
