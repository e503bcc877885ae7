"""The pieces of the multi-agent PPO learners: networks, and saved actors as policies.

(Their normalizers, `RunningNorm` and `RewardScaler`, are `advgame.agents.marl.norm`.)

* `TeamModel`: one `GaussianActor` per protagonist on its local observation, and the critic:
  MAPPO's centralised critic on the global state (one value head per protagonist, since a reward
  disruptor may perturb the agents' observed rewards differently; with a shared reward the heads
  agree), or IPPO's one critic per protagonist on its local observation.
* `TeamSnapshot` / `NumpyMLP`: numpy copies of the current networks for acting step by step
  (torch's per-call overhead dominates 64-unit MLPs at batch sizes of a few views).
* `TorchActorCheckpoint`: a picklable `PolicySpec` that rebuilds one saved actor and its frozen
  observation normalizer as a `TorchActorPolicy` in any process.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from torch import nn

from advgame.agents.marl.norm import RunningNorm
from advgame.core.numpy_net import NetCache, NumpyNet
from advgame.core.policy import AgentInfo
from advgame.errors import ConfigError

__all__ = [
    "ACTORS_FORMAT",
    "GaussianActor",
    "NumpyMLP",
    "TeamModel",
    "TeamSnapshot",
    "TorchActorCheckpoint",
    "TorchActorPolicy",
    "actor_record",
]

ACTORS_FORMAT = "advgame-torch-actors-v1"
"""Format tag of an actors file written by `TeamLearner.save`."""


def _mlp(sizes: Sequence[int], gain_out: float, generator: torch.Generator) -> nn.Sequential:
    """Tanh MLP, orthogonal weights (gain √2 hidden, `gain_out` last), zero biases (as SB3)."""
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        linear = nn.Linear(sizes[i], sizes[i + 1])
        last = i == len(sizes) - 2
        nn.init.orthogonal_(linear.weight, gain_out if last else math.sqrt(2), generator=generator)
        nn.init.zeros_(linear.bias)
        layers += [linear] if last else [linear, nn.Tanh()]
    return nn.Sequential(*layers)


class GaussianActor(nn.Module):
    """A diagonal Gaussian policy: an MLP mean of the observation, a state-independent log-std."""

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden: Sequence[int],
        log_std_init: float = 0.0,
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__()
        gen = generator if generator is not None else torch.Generator()
        self.arch = {"obs_dim": obs_dim, "act_dim": act_dim, "hidden": list(hidden)}
        self.mean = _mlp([obs_dim, *hidden, act_dim], 0.01, gen)
        self.log_std = nn.Parameter(torch.full((act_dim,), float(log_std_init)))

    def log_prob(
        self, obs: torch.Tensor, actions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Log-probabilities of `actions` at `obs` (summed over dims) and the entropy."""
        return _log_prob(self.mean(obs), self.log_std, actions), self.entropy()

    def entropy(self) -> torch.Tensor:
        """The Gaussian's entropy (summed over dims; the same at every observation)."""
        return (self.log_std + _HALF_LOG_2PI_E).sum()


_HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)
_HALF_LOG_2PI_E = 0.5 + _HALF_LOG_2PI


def _log_prob(mu: torch.Tensor, log_std: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Diagonal Gaussian log-density, summed over the last axis (no `Distribution` overhead)."""
    z = (x - mu) * torch.exp(-log_std)
    return (-0.5 * z * z - log_std - _HALF_LOG_2PI).sum(-1)


class NumpyMLP:
    """A frozen numpy copy of a Linear/Tanh `nn.Sequential`, for acting a few samples at a time.

    For one to a few views per step, torch's per-call overhead is several times the arithmetic
    of a 64-unit MLP; collection, `TeamLearner.predict` and `TorchActorPolicy` run this copy.
    """

    def __init__(self, net: nn.Module) -> None:
        self.layers: list[tuple[np.ndarray, np.ndarray] | None] = []
        for module in net.children():
            if isinstance(module, nn.Linear):
                weight = module.weight.detach().numpy().T.copy()
                self.layers.append((weight, module.bias.detach().numpy().copy()))
            elif isinstance(module, nn.Tanh):
                self.layers.append(None)
            else:
                raise TypeError(f"NumpyMLP copies Linear and Tanh layers only, not {module}.")
        self._row_invariant: bool | None = None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The network's output for a float32 batch ``[batch, in]``."""
        for layer in self.layers:
            x = np.tanh(x) if layer is None else x @ layer[0] + layer[1]
        return x

    def rows(self, x: np.ndarray) -> np.ndarray | None:
        """The output of each row of ``[batch, in]`` exactly as `__call__` gives it alone.

        Each linear layer runs as a stack of one-row products (``[batch, 1, in] @ W``), the
        shape a lone row has; None if a probe (once per network) finds numpy's stacked product
        differs from the lone one in any bit here, and the caller goes row by row.
        """
        return self._stacked(x) if self.row_invariant else None

    @property
    def row_invariant(self) -> bool:
        """Whether `rows` reproduces lone rows here (probed once)."""
        if self._row_invariant is None:
            self._row_invariant = self._probe()
        return self._row_invariant

    def _stacked(self, x: np.ndarray) -> np.ndarray:
        h = x[:, None, :]
        for layer in self.layers:
            h = np.tanh(h) if layer is None else np.matmul(h, layer[0]) + layer[1]
        return h[:, 0, :]

    def _probe(self) -> bool:
        rng = np.random.default_rng(0)
        width = next(w.shape[0] for w in (lay[0] for lay in self.layers if lay is not None))
        for n in (2, 3, 8, 33):
            x = rng.normal(size=(n, width)).astype(np.float32)
            alone = np.concatenate([self(x[i : i + 1]) for i in range(n)])
            if not np.array_equal(self._stacked(x), alone):
                return False
        return True


class TeamSnapshot:
    """The team's current networks as numpy functions: what a rollout is collected with."""

    def __init__(self, model: TeamModel) -> None:
        self.agents = list(model.agents)
        self.means = {a: NumpyMLP(model.actor(a).mean) for a in self.agents}
        self.log_std = {a: model.actor(a).log_std.detach().numpy().copy() for a in self.agents}
        self.critics = {k: NumpyMLP(c) for k, c in model.critics.items()}
        self.centralised = model.centralised

    def sample(
        self, obs: Mapping[str, np.ndarray], noise: Mapping[str, np.ndarray]
    ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Actions ``mean + std * noise`` per agent and their log-probabilities ``[batch, agents]``."""
        actions, logp = {}, []
        for a in self.agents:
            actions[a] = self.means[a](obs[a]) + np.exp(self.log_std[a]) * noise[a]
            logp.append((-0.5 * noise[a] ** 2 - self.log_std[a] - _HALF_LOG_2PI).sum(-1))
        return actions, np.stack(logp, -1).astype(np.float32)

    def values(self, obs: Mapping[str, np.ndarray], state: np.ndarray | None) -> np.ndarray:
        """Each agent's value estimate, ``[batch, agents]`` (as `TeamModel.values`)."""
        if self.centralised:
            assert state is not None, "MAPPO's critic needs the global state"
            return self.critics["central"](state)
        return np.concatenate([self.critics[a](obs[a]) for a in self.agents], axis=-1)


class TeamModel(nn.Module):
    """Every protagonist's actor and the team's critic(s), trained by one Adam optimizer.

    Args:
        obs_dims: observation size per protagonist (in team order).
        act_dims: action size per protagonist.
        state_dim: the global state size for MAPPO's centralised critic; None for IPPO.
        hidden: hidden layer sizes of every network.
        log_std_init: initial log-std of every actor.
        generator: the torch generator the weights are drawn from.

    """

    def __init__(
        self,
        obs_dims: Mapping[str, int],
        act_dims: Mapping[str, int],
        state_dim: int | None,
        hidden: Sequence[int],
        log_std_init: float,
        generator: torch.Generator,
    ) -> None:
        super().__init__()
        self.agents = list(obs_dims)
        self.actors = nn.ModuleDict(
            {
                a: GaussianActor(obs_dims[a], act_dims[a], hidden, log_std_init, generator)
                for a in self.agents
            }
        )
        self.centralised = state_dim is not None
        if state_dim is not None:
            self.critics = nn.ModuleDict(
                {"central": _mlp([state_dim, *hidden, len(self.agents)], 1.0, generator)}
            )
        else:
            self.critics = nn.ModuleDict(
                {a: _mlp([obs_dims[a], *hidden, 1], 1.0, generator) for a in self.agents}
            )

    def values(self, obs: Mapping[str, torch.Tensor], state: torch.Tensor | None) -> torch.Tensor:
        """Each protagonist's value estimate, ``[batch, agents]``."""
        if self.centralised:
            assert state is not None, "MAPPO's critic needs the global state"
            return self.critics["central"](state)
        return torch.cat([self.critics[a](obs[a]) for a in self.agents], dim=-1)

    def actor(self, agent: str) -> GaussianActor:
        """`agent`'s actor."""
        return cast(GaussianActor, self.actors[agent])

    def snapshot(self) -> TeamSnapshot:
        """Numpy copies of the current networks (for collecting a rollout)."""
        return TeamSnapshot(self)

    def clip_grad_norms(self, max_norm: float) -> None:
        """Clip the gradient norm of each actor and each critic separately."""
        for module in [*self.actors.values(), *self.critics.values()]:
            nn.utils.clip_grad_norm_(module.parameters(), max_norm)


def actor_record(
    actor: GaussianActor, norm: RunningNorm | None, low: np.ndarray, high: np.ndarray
) -> dict[str, Any]:
    """What an actors file holds for one protagonist (tensors and plain values only)."""
    return {
        "arch": dict(actor.arch),
        "state_dict": {k: v.detach().clone() for k, v in actor.state_dict().items()},
        "normalizer": None if norm is None else norm.state_dict(),
        "low": torch.from_numpy(np.asarray(low, dtype=np.float32).copy()),
        "high": torch.from_numpy(np.asarray(high, dtype=np.float32).copy()),
    }


class TorchActorPolicy:
    """A saved actor behind its frozen observation normalizer, as an advgame `Policy`.

    Acts with the Gaussian's mean (`deterministic`) or samples it with its own generator
    (reseeded by `reset(seed)`); actions are clipped into the action space, as in training.
    It is an `advgame.core.policy.WhiteBox` (actor only: MAD attacks it; the critic is not saved).
    """

    def __init__(self, record: Mapping[str, Any], deterministic: bool = True) -> None:
        arch = record["arch"]
        actor = GaussianActor(arch["obs_dim"], arch["act_dim"], arch["hidden"])
        actor.load_state_dict(record["state_dict"])
        self.actor = actor.eval()
        self.mean = NumpyMLP(actor.mean)
        self.std = actor.log_std.detach().exp().numpy()
        self.norm: RunningNorm | None = None
        if record["normalizer"] is not None:
            self.norm = RunningNorm((arch["obs_dim"],))
            self.norm.load_state_dict(record["normalizer"])
        self.low, self.high = record["low"].numpy(), record["high"].numpy()
        self.deterministic = deterministic
        self._rng = np.random.default_rng(0)
        self._record = record  # kept alive: its id is the batch key's
        self._numpy = NetCache()

    def reset(self, seed: int | None = None) -> None:
        """Reseed the action sampling (a stochastic policy's only randomness)."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)

    @property
    def batch_key(self) -> tuple | None:
        """Equal for deterministic policies of one loaded actor (`act_batch` serves them all).

        None for a sampling policy (each game draws from its own generator) or where the
        stacked forward pass does not reproduce lone rows (`NumpyMLP.rows`).
        """
        if not self.deterministic or not self.mean.row_invariant:
            return None
        return ("torch-actor", id(self._record))

    def act_batch(self, observations: Any) -> np.ndarray:
        """`act` of every row of ``[batch, obs]``, row for row what `act` gives it alone."""
        obs = np.asarray(observations, dtype=np.float64)
        x = self.norm.normalize(obs) if self.norm is not None else obs.astype(np.float32)
        action = self.mean.rows(x)
        if action is None or not self.deterministic:
            return np.stack([self.act(o) for o in observations])
        return np.clip(action, self.low, self.high).astype(np.float32)

    def act(self, observation: Any) -> np.ndarray:
        """The action for one raw observation."""
        obs = np.asarray(observation, dtype=np.float64)[None]
        x = self.norm.normalize(obs) if self.norm is not None else obs.astype(np.float32)
        action = self.mean(x)[0]
        if not self.deterministic:
            action = action + self.std * self._rng.standard_normal(action.shape)
        return np.clip(action, self.low, self.high).astype(np.float32)

    # -- white-box access (`advgame.core.policy.WhiteBox`): forward passes only ------------------
    def action_mean(self, obs: torch.Tensor) -> torch.Tensor:
        """The Gaussian's mean for a batch of raw observations, behind the frozen normalizer."""
        x = obs
        if self.norm is not None:
            mean = torch.as_tensor(self.norm.mean, dtype=torch.float32)
            std = torch.as_tensor(self.norm.std, dtype=torch.float32)
            x = ((obs - mean) / std).clamp(-self.norm.clip, self.norm.clip)
        return self.actor.mean(x)

    def numpy_net(self, head: str) -> NumpyNet | None:
        """The actor's mean (``"mean"``) as a `NumpyNet` behind the normalizer; no value head."""
        if head != "mean":
            return None
        norm = None if self.norm is None else (self.norm.mean, self.norm.std, self.norm.clip)
        return self._numpy.get("mean", [self.actor.mean], norm)

    def action_std(self) -> torch.Tensor:
        """The state-independent action std."""
        return torch.as_tensor(self.std, dtype=torch.float32)

    def value(self, obs: torch.Tensor) -> None:
        """Actors files hold no critic."""
        return None

    def q_value(self, obs: torch.Tensor, action: torch.Tensor) -> None:
        """Actors files hold no critic."""
        return None


@functools.lru_cache(maxsize=32)
def _load_actors(path: str, mtime_ns: int) -> dict[str, Any]:
    """An actors file, cached per process (keyed on its modification time too)."""
    data = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(data, dict) or data.get("format") != ACTORS_FORMAT:
        raise ConfigError(f"{path} is not an advgame actors file ({ACTORS_FORMAT}).")
    return data


@dataclass(frozen=True)
class TorchActorCheckpoint:
    """One protagonist's actor saved by `TeamLearner.save`, as a picklable policy spec.

    Example:
        ``TorchActorCheckpoint("runs/ma/checkpoints/iter_0003/mappo_actors.pt", "agent_0")``

    """

    path: str
    """The actors file (``<algo>_actors.pt``), which holds every protagonist's actor."""
    agent: str
    """Whose actor to build (the protagonist it was trained as)."""
    deterministic: bool = True
    """Act with the Gaussian's mean instead of sampling."""

    def build(self, info: AgentInfo) -> TorchActorPolicy:
        """Load the actor (cached per process) and check it fits `info`'s spaces."""
        if not Path(self.path).exists():
            raise ConfigError(f"No actors file at {self.path!r}.")
        actors = _load_actors(str(self.path), os.stat(self.path).st_mtime_ns)["actors"]
        if self.agent not in actors:
            raise ConfigError(
                f"{self.path} has no actor for {self.agent!r}; it holds {sorted(actors)}."
            )
        record = actors[self.agent]
        want = (tuple(info.observation_space.shape or ()), info.action_shape)
        have = ((record["arch"]["obs_dim"],), (record["arch"]["act_dim"],))
        if want != have:
            raise ConfigError(
                f"The actor of {self.agent!r} in {self.path} maps observations {have[0]} to "
                f"actions {have[1]}, but {info.agent!r} observes {want[0]} and acts {want[1]}."
            )
        return TorchActorPolicy(record, self.deterministic)
