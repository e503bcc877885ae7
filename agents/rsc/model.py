"""RSC's causal world model and its state perturbation (Ding et al., NeurIPS 2023, arXiv 2307.07907).

RSC (robust state-confounded SAC) makes the agent meet states in which one part of the state
has moved while the rest stayed put, as if the unobserved confounder that ties them together
had changed, and asks a world model that only uses *causal* parents what would follow:

* `CausalWorldModel`: a structural causal model from ``(s, a)`` to ``(s', r)``. A learnable
  binary graph (one Bernoulli edge per input and output dimension, logits ``φ``) masks the
  inputs of each output's own MLP; during training each row's graph is drawn edge by edge, and
  the prediction loss (with the score function's gradient for ``φ``) plus the sparsity term
  ``λ · Σ −log(1 − σ(φ))`` train ``φ`` with the networks: an edge stays while dropping it costs
  the prediction more than ``λ``. Each state variable's own past, ``s[i] → s'[i]``, is an edge
  that is always present (`losses` says why; ``graph_draws="relaxed"`` and
  ``keep_self_edges=False`` give the Gumbel-Softmax reading the first runs trained with).
* `perturb_states`: the paper's Eq. 7. For each perturbed row ``t`` one state dimension ``i``
  is drawn, and ``s_t[i]`` is replaced by ``s_k[i]`` of the row ``k`` of the batch that
  maximises ``(s_t[i] − s_k[i])² / Σ_{j≠i} (s_t[j] − s_k[j])²``: the row most different in
  ``i`` and most similar in the rest. A small clipped Gaussian jitter (the Robust Gymnasium
  table's ``sigma`` and ``bound``) is added to the perturbed state.

Choices the paper leaves open (also in docs/causal.md): differences in Eq. 7 are measured in
units of each dimension's standard deviation over the batch; inputs and targets of the world
model are standardised with running statistics; the prediction loss is a Gaussian negative
log-likelihood with a fixed standard deviation (the table's ``vae sigma``); augmentation uses
the graph's most probable edges (probability > 0.5).
"""

from __future__ import annotations

import math
from typing import Any

import torch as th
from torch import nn
from torch.nn import functional as F

__all__ = ["GRAPH_DRAWS", "CausalWorldModel", "RunningNorm", "perturb_states"]

GRAPH_DRAWS = ("hard", "relaxed")
"""How the world model's loss draws each row's graph (`CausalWorldModel.losses`)."""


class RunningNorm(nn.Module):
    """Per-dimension running mean, variance, lowest and highest value, merged batch by batch.

    All are saved as buffers. ``low`` and ``high`` (the range of every row merged so far; an
    empty one, +inf to −inf, before the first) are newer than the rest: a state dict saved
    before them loads with the empty range, and the range grows from the next batch on.
    """

    mean: th.Tensor
    var: th.Tensor
    count: th.Tensor
    low: th.Tensor
    high: th.Tensor

    def __init__(self, size: int) -> None:
        super().__init__()
        self.register_buffer("mean", th.zeros(size))
        self.register_buffer("var", th.ones(size))
        self.register_buffer("count", th.zeros(()))
        self.register_buffer("low", th.full((size,), th.inf))
        self.register_buffer("high", th.full((size,), -th.inf))

    def _load_from_state_dict(self, state_dict: dict, prefix: str, *args: Any) -> None:
        for name in ("low", "high"):  # checkpoints from before 7 Dec 2026 have no range
            state_dict.setdefault(prefix + name, getattr(self, name).clone())
        super()._load_from_state_dict(state_dict, prefix, *args)

    @th.no_grad()
    def update(self, x: th.Tensor) -> None:
        """Merge the statistics of the rows of `x` (Chan et al.'s parallel update)."""
        n = float(x.shape[0])
        total = self.count + n
        delta = x.mean(0) - self.mean
        m2 = (
            self.var * self.count + x.var(0, unbiased=False) * n + delta**2 * self.count * n / total
        )
        self.mean += delta * n / total
        self.var.copy_(m2 / total)
        self.count.fill_(total)
        th.minimum(self.low, x.min(0).values, out=self.low)
        th.maximum(self.high, x.max(0).values, out=self.high)

    def clip(self, x: th.Tensor) -> th.Tensor:
        """`x` clipped, per dimension, to the range of the rows merged so far (none: as it is)."""
        return th.where(self.low <= self.high, th.minimum(th.maximum(x, self.low), self.high), x)

    def normalize(self, x: th.Tensor) -> th.Tensor:
        """``(x − mean) / std``."""
        return (x - self.mean) / th.sqrt(self.var + 1e-8)

    def denormalize(self, z: th.Tensor) -> th.Tensor:
        """The inverse of `normalize`."""
        return z * th.sqrt(self.var + 1e-8) + self.mean


def _uniform(*shape: int, fan_in: int) -> nn.Parameter:
    bound = 1.0 / math.sqrt(fan_in)  # nn.Linear's default initialisation
    return nn.Parameter(th.empty(*shape).uniform_(-bound, bound))


class CausalWorldModel(nn.Module):
    """``(s, a) -> (s', r)`` with one masked MLP per output dimension and a learned causal graph.

    Args:
        obs_dim: size of the (flat) state.
        act_dim: size of the action.
        hidden: width of each output's two hidden layers.
        lr: Adam step size of the networks.
        graph_lr: Adam step size of the graph logits.
        sparsity: λ, the weight of the sparsity term (`losses`: on −log P(edge absent) for hard draws,
            on the expected number of edges for relaxed ones).
        temperature: τ of the Gumbel-Softmax draws of the graph.
        sigma: the fixed standard deviation of the Gaussian likelihood (standardised units).
        init_logit: initial logit of every edge (2: each edge starts present with p ≈ 0.88).
        graph_draws: ``"hard"`` (Bernoulli draws, score-function gradient) or ``"relaxed"``
            (Gumbel-Softmax draws): see `losses`.
        keep_self_edges: give every state output its own past, ``s[i] → s'[i]``, as an edge
            that is always present, out of the sparsity term and the graph's draws.
        clip_to_support: clip each predicted ``(s', r)`` dimension to the range of the targets
            the model has trained on (`predict`).

    """

    kept: th.Tensor

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden: int = 64,
        lr: float = 1e-3,
        graph_lr: float = 3e-2,
        sparsity: float = 3e-3,
        temperature: float = 1.0,
        sigma: float = 1.0,
        init_logit: float = 2.0,
        graph_draws: str = "hard",
        keep_self_edges: bool = True,
        clip_to_support: bool = False,
    ) -> None:
        super().__init__()
        self.clip_to_support = clip_to_support
        self.obs_dim, self.act_dim = obs_dim, act_dim
        n_in, n_out = obs_dim + act_dim, obs_dim + 1
        self.sparsity, self.temperature, self.sigma = sparsity, temperature, sigma
        if graph_draws not in GRAPH_DRAWS:
            raise ValueError(f"graph_draws must be one of {GRAPH_DRAWS}, got {graph_draws!r}.")
        self.graph_draws, self.keep_self_edges = graph_draws, keep_self_edges
        self.graph_logits = nn.Parameter(th.full((n_out, n_in), float(init_logit)))
        """φ: row o, column j is the logit of the edge from input j to output o."""
        self.w1, self.b1 = (
            _uniform(n_out, n_in, hidden, fan_in=n_in),
            _uniform(n_out, hidden, fan_in=n_in),
        )
        self.w2, self.b2 = (
            _uniform(n_out, hidden, hidden, fan_in=hidden),
            _uniform(n_out, hidden, fan_in=hidden),
        )
        self.w3, self.b3 = _uniform(n_out, hidden, fan_in=hidden), _uniform(n_out, fan_in=hidden)
        self.inputs, self.targets = RunningNorm(n_in), RunningNorm(n_out)
        kept = th.zeros(n_out, n_in)
        if keep_self_edges:
            kept[:obs_dim, :obs_dim].fill_diagonal_(1.0)
        self.register_buffer("kept", kept, persistent=False)
        """1 for each edge that is always present (``s[i] → s'[i]`` when kept), else 0."""
        weights = [self.w1, self.b1, self.w2, self.b2, self.w3, self.b3]
        self.optimizer = th.optim.Adam(
            [{"params": weights, "lr": lr}, {"params": [self.graph_logits], "lr": graph_lr}],
            fused=True,
        )

    def edge_probabilities(self) -> th.Tensor:
        """``σ(φ)``, 1 on the kept edges: shape (obs_dim + 1, obs_dim + act_dim), outputs ``(s', r)`` by inputs ``(s, a)``."""
        return th.maximum(th.sigmoid(self.graph_logits), self.kept)

    def sample_graph(self, rows: int) -> th.Tensor:
        """One relaxed graph per row (entries in (0, 1)) by the binary Gumbel-Softmax at τ.

        The two-class Gumbel-Softmax over (edge: ``φ``, no edge: 0) gives the edge
        ``exp((φ + g₁)/τ) / (exp((φ + g₁)/τ) + exp(g₀/τ)) = σ((φ + g₁ − g₀)/τ)``, and the
        difference of two standard Gumbels is a standard logistic, ``log u − log(1 − u)``: so
        one uniform draw and a sigmoid per edge, the same distribution and gradient as
        ``F.gumbel_softmax`` on the stacked logits at a small part of its cost (its
        exponential draws and two-class softmax took 45 % of RSC's update on RS-LiftCausal).
        """
        tiny = th.finfo(self.graph_logits.dtype).tiny
        u = th.rand(rows, *self.graph_logits.shape).clamp_(tiny, 1.0 - 2**-24)
        return th.sigmoid((self.graph_logits + (th.log(u) - th.log1p(-u))) / self.temperature)

    def mode_graph(self) -> th.Tensor:
        """The most probable graph: the edges with probability > 0.5 (the kept ones included)."""
        return (self.edge_probabilities() > 0.5).float()

    @th.no_grad()
    def draw_graph(self, rows: int) -> th.Tensor:
        """One hard graph per row, each edge present with probability ``σ(φ)`` (kept ones: 1).

        Shape (rows, outputs, inputs), laid out output-major in memory (the transpose of a
        contiguous (outputs, rows, inputs) tensor), the layout `forward`'s batched products
        take without a copy. A uniform draw below the edge's probability is a Bernoulli draw;
        for a 128-row door batch (64 × 70 edges) the uniforms and the comparison took 3.2-4.7 ms
        where ``th.bernoulli`` took 6.0 ms (torch's profiler, one thread, 7 Dec; in the whole
        learner the difference was within that day's noise: benchmarks/bench_causal.py,
        ``rsc (th.bernoulli)``).
        """
        probs = self.edge_probabilities()
        u = th.rand(probs.shape[0], rows, probs.shape[1])
        return (u < probs.unsqueeze(1)).float().transpose(0, 1)

    def forward(self, inputs: th.Tensor, graph: th.Tensor) -> th.Tensor:
        """Standardised ``(s', r)`` from standardised ``(s, a)`` rows, output o seeing ``graph[o]``.

        `graph`: one graph for every row, (outputs, inputs), or one per row, (rows, outputs,
        inputs). Each output's MLP runs as one batched matrix product over the outputs.
        """
        # (outputs, rows, inputs), each output's row of the graph on every row of inputs
        graph = graph.unsqueeze(1) if graph.dim() == 2 else graph.transpose(0, 1)
        masked = inputs.unsqueeze(0) * th.maximum(graph, self.kept.unsqueeze(1))
        h = F.relu(th.baddbmm(self.b1.unsqueeze(1), masked, self.w1))
        h = F.relu(th.baddbmm(self.b2.unsqueeze(1), h, self.w2))
        return (th.bmm(h, self.w3.unsqueeze(2)).squeeze(2) + self.b3.unsqueeze(1)).T

    def losses(
        self, obs: th.Tensor, actions: th.Tensor, next_obs: th.Tensor, rewards: th.Tensor
    ) -> tuple[th.Tensor, th.Tensor]:
        """The prediction loss under drawn graphs and the sparsity penalty, per batch.

        ``graph_draws = "hard"`` (the default): each row's graph is drawn edge by edge, present
        with probability ``σ(φ)``, so an output trains on exactly the inputs its graph gives it,
        as it predicts for augmentation under the most probable graph. The logits' gradient is
        the score function's, ``mean_rows (L − b) (m − σ(φ))`` per edge, with ``L`` the row's
        loss of that output and ``b`` the mean of the batch's other rows (unbiased: it compares
        the loss with and without each edge). The returned loss has the prediction loss's
        value; the score term adds only its gradient.

        ``"relaxed"``: binary Gumbel-Softmax draws, never exactly 0, and their reparameterised
        gradient. An input masked by 0.005 still tells a network its sign, so under relaxed
        draws an edge its output needs (a colour that stays the colour) lost its logit to the
        sparsity term while the loss stayed low, and the most probable graph then cut it
        (docs/causal.md, "The graph's draws").
        """
        x, y = self._standardised(obs, actions, next_obs, rewards)
        learned = 1 - self.kept
        if self.graph_draws == "relaxed":
            penalty = self.sparsity * (self.edge_probabilities() * learned).sum()
            pred = self(x, self.sample_graph(len(x)))
            return ((pred - y) ** 2).sum(dim=1).mean() / (2 * self.sigma**2), penalty
        # −log P(edge absent): its gradient σ(φ) does not vanish on a confident edge
        penalty = self.sparsity * (F.softplus(self.graph_logits) * learned).sum()
        rows = len(x)
        graph = self.draw_graph(rows)
        per_row = ((self(x, graph) - y) ** 2) / (2 * self.sigma**2)  # (rows, outputs)
        with th.no_grad():  # leave-one-out baseline: L − mean of the other rows
            advantage = (per_row - per_row.mean(dim=0)) * rows / max(rows - 1, 1)
            # the score function's gradient, mean_rows (L − b)(m − σ(φ)), as one batched
            # product over the outputs (d log P(m) / dφ = m − σ(φ) for a Bernoulli edge)
            drawn = th.bmm(advantage.T.unsqueeze(1), graph.transpose(0, 1)).squeeze(1)
            score_grad = drawn - advantage.sum(dim=0).unsqueeze(1) * th.sigmoid(self.graph_logits)
            score_grad *= learned / rows
        score = (self.graph_logits * score_grad).sum()
        return per_row.sum(dim=1).mean() + score - score.detach(), penalty

    def _standardised(
        self, obs: th.Tensor, actions: th.Tensor, next_obs: th.Tensor, rewards: th.Tensor
    ) -> tuple[th.Tensor, th.Tensor]:
        """The model's input ``(s, a)`` and target ``(s', r)`` rows in standardised units."""
        x = self.inputs.normalize(th.cat([obs, actions], dim=1).float())
        return x, self.targets.normalize(th.cat([next_obs, rewards.reshape(-1, 1)], dim=1).float())

    def update(
        self, obs: th.Tensor, actions: th.Tensor, next_obs: th.Tensor, rewards: th.Tensor
    ) -> float:
        """Merge the batch into the running statistics, then one Adam step; returns the loss."""
        self.inputs.update(th.cat([obs, actions], dim=1).float())
        self.targets.update(th.cat([next_obs, rewards.reshape(-1, 1)], dim=1).float())
        nll, penalty = self.losses(obs, actions, next_obs, rewards)
        loss = nll + penalty
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        return float(loss.item())

    @th.no_grad()
    def mode_errors(
        self, obs: th.Tensor, actions: th.Tensor, next_obs: th.Tensor, rewards: th.Tensor
    ) -> th.Tensor:
        """Each output's mean squared error, standardised, under the most probable graph.

        What the augmented rows are generated under (`predict`); the training loss draws a
        graph per row instead, so the two can differ. Shape (obs_dim + 1,): ``s'`` then ``r``;
        an output predicted no better than its mean scores about 1.
        """
        x, y = self._standardised(obs, actions, next_obs, rewards)
        return ((self(x, self.mode_graph()) - y) ** 2).mean(dim=0)

    def mode_error(
        self, obs: th.Tensor, actions: th.Tensor, next_obs: th.Tensor, rewards: th.Tensor
    ) -> float:
        """The mean of `mode_errors` over the outputs (``train/model_error_mode``)."""
        return float(self.mode_errors(obs, actions, next_obs, rewards).mean())

    @th.no_grad()
    def predict(self, obs: th.Tensor, actions: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """``(s', r)`` under the most probable graph, in the data's own units (r: shape (n, 1)).

        With `clip_to_support`, each dimension is clipped to the range of the targets trained
        on, so no generated next state or reward lies beyond what the data has shown.
        """
        x = self.inputs.normalize(th.cat([obs, actions], dim=1).float())
        out = self.targets.denormalize(self(x, self.mode_graph()))
        if self.clip_to_support:
            out = self.targets.clip(out)
        return out[:, : self.obs_dim], out[:, self.obs_dim :]


@th.no_grad()
def perturb_states(
    states: th.Tensor, rows: int, sigma: float = 0.01, bound: float = 0.01
) -> tuple[th.Tensor, th.Tensor]:
    """Eq. 7 on the first `rows` states against the whole batch `states`; plus clipped jitter.

    Returns the perturbed rows and, per row, the dimension that was swapped.
    """
    pool = states.float()
    count, dims = pool.shape
    z = pool / pool.std(dim=0).clamp_min(1e-6) if count > 1 else pool
    picked = th.randint(dims, (rows,))
    diff2 = (z[:rows, None, :] - z[None, :, :]) ** 2  # (rows, batch, dims)
    moved = diff2.gather(2, picked.view(rows, 1, 1).expand(rows, count, 1)).squeeze(2)
    score = moved / (diff2.sum(dim=2) - moved + 1e-8)
    own = th.arange(rows)
    score[own, own] = -th.inf  # a row is not its own donor
    donors = score.argmax(dim=1)
    out = pool[:rows].clone()
    out[own, picked] = pool[donors, picked]
    jitter = (th.randn_like(out) * sigma).clamp(-bound, bound)
    return out + jitter, picked
