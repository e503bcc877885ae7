"""A saved sb3-contrib ``RecurrentPPO`` (an LSTM policy) as a policy that carries its memory.

`RecurrentSB3Policy` is `advgame.agents.common.sb3_policy.SB3Policy` with a hidden state: `reset`
zeroes it at every episode start, and every `act` advances it on the observation the policy
was given (under an observation attack, the perturbed one, as it would be in deployment).
One `act` is one call of sb3-contrib's own recurrent forward pass, with the same operations
as ``RecurrentPPO.predict``, so a model trained with plain sb3-contrib plays the same actions
bit for bit (``tests/test_recurrent.py``).

It is a `advgame.core.policy.WhiteBox` too: `action_mean` and `value` evaluate a batch of
observations *with the state the policy carries now* (the state it will act with at this
step), so a white-box attack computes the perturbation of step t with the victim's memory at
t, without advancing it. The actor's state advances with every action; the value head's
state (a separate critic LSTM, sb3-contrib's default) is only needed by attacks that read
`value`, so the observations since the episode start are kept and the critic catches up on
them when asked.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from advgame.agents.common.sb3_policy import SB3Policy
from advgame.core.numpy_lstm import LSTMCell, recurrent_modules
from advgame.core.numpy_net import NumpyNet, weights_stamp
from advgame.errors import ConfigError

__all__ = ["RecurrentSB3Policy", "is_recurrent"]


def is_recurrent(model: Any) -> bool:
    """Whether `model`'s policy is an sb3-contrib recurrent (LSTM) policy."""
    return hasattr(getattr(model, "policy", None), "lstm_actor")


class RecurrentSB3Policy(SB3Policy):
    """A ``RecurrentPPO`` model's LSTM policy with its memory, behind its frozen normalizer.

    Args:
        model: the ``RecurrentPPO`` model (its ``policy`` is used; nothing is trained).
        obs_mean: the frozen normalizer's mean, or None if unnormalized.
        obs_var: the frozen normalizer's variance, or None if unnormalized.
        deterministic: act with the distribution's mode instead of sampling.
        clip_obs: the normalizer's clip range (SB3 `VecNormalize` default 10).
        epsilon: added to the variance before its square root.

    """

    recurrent = True
    """Marks a policy whose action depends on what it saw before in the episode."""

    def __init__(
        self,
        model: Any,
        obs_mean: np.ndarray | None = None,
        obs_var: np.ndarray | None = None,
        deterministic: bool = True,
        clip_obs: float = 10.0,
        epsilon: float = 1e-8,
    ) -> None:
        if not is_recurrent(model):
            raise ConfigError(
                f"RecurrentSB3Policy needs an sb3-contrib RecurrentPPO model, got "
                f"{type(model).__name__}; use SB3Policy for feed-forward policies."
            )
        super().__init__(model, obs_mean, obs_var, deterministic, clip_obs, epsilon)
        self._actor: tuple[Any, Any]
        self._critic: tuple[Any, Any]
        self._seen: list[Any]  # policy inputs since the episode start (critic catch-up)
        self._critic_at: int
        self._group: tuple[Any, tuple[Any, NumpyNet] | None] | None = None  # `_group_net`
        self._forget()

    def _zeros(self) -> tuple[Any, Any]:
        import torch

        shape = self.model.policy.lstm_hidden_state_shape  # (layers, 1, hidden)
        return torch.zeros(shape), torch.zeros(shape)

    # -- playing -------------------------------------------------------------------------------
    def reset(self, seed: int | None = None) -> None:
        """Start an episode: zero the memory (and seed sampling, as `SB3Policy.reset`)."""
        super().reset(seed)
        self._forget()

    def _forget(self) -> None:
        """Zero the actor's and the critic's memory; nothing seen yet this episode."""
        self._actor, self._critic = self._zeros(), self._zeros()
        self._seen, self._critic_at = [], 0

    @property
    def batch_key(self) -> tuple | None:
        """None: each copy carries its own memory, so copies are asked one at a time.

        (A batched LSTM pass would differ from the one-row pass in the last bit, and a chaotic
        simulator turns that into another episode.)
        """
        return None

    @property
    def inexact_batch_key(self) -> tuple:
        """Equal for copies of one network and normalizer: `act_group` may serve them together.

        Only callers that accept last-bit differences from play alone use it (training
        rollouts: `advgame.core.policy.act_batch` with ``exact=False``).
        """
        return ("recurrent", *self._network_key())

    def act_group(self, policies: Any, observations: np.ndarray) -> Any:
        """``policies[i].act(observations[i])`` for copies of this network, in one LSTM pass.

        Each copy's memory goes in as one column of the batch and comes back advanced on its
        own row. torch's batched LSTM kernel rounds differently from its one-row pass, so the
        actions may differ from `act`'s in the last bit.
        """
        import torch

        rows = self._normalize(np.asarray(observations))
        x = torch.as_tensor(rows)
        # through methods, not attributes: a wrapper that forwards to its policy (a mixture
        # drawing one per episode) then reads and writes the memory of the policy it plays
        memories = [p._memory() for p in policies]
        fast = self._group_net()
        if fast is not None:  # NumPy: the same operations, without torch's per-call overhead
            cell, head = fast
            h_np, c_np = cell.step(
                rows,
                np.stack([m[0].numpy().reshape(-1) for m in memories]),
                np.stack([m[1].numpy().reshape(-1) for m in memories]),
            )
            shape = (1, 1, cell.hidden)
            for i, p in enumerate(policies):
                memory = (torch.from_numpy(h_np[i].reshape(shape)),
                          torch.from_numpy(c_np[i].reshape(shape)))  # fmt: skip
                p._advanced(memory, x[i : i + 1])
            mean = head.forward(h_np)[0]
            return self._in_box(mean.reshape((-1, *self.model.action_space.shape)))
        h = torch.cat([m[0] for m in memories], dim=1)
        c = torch.cat([m[1] for m in memories], dim=1)
        actions, (h, c) = self._forward(x, (h, c))
        for i, p in enumerate(policies):
            p._advanced((h[:, i : i + 1].clone(), c[:, i : i + 1].clone()), x[i : i + 1])
        return actions

    def _group_net(self) -> tuple[Any, NumpyNet] | None:
        """`act_group`'s NumPy pass: the actor's LSTM cell and the mean head after it, or None.

        Only for a deterministic policy whose mean head `recurrent_modules` covers (the mode of
        a plain Gaussian) and one LSTM layer; copied again when the weights change (a live
        learner's), as `numpy_net`'s copies are.
        """
        if not self.deterministic:
            return None
        picked = recurrent_modules(self.model.policy, "mean")
        if picked is None or picked[1] != "actor":
            return None
        lstm, *rest = picked[0]
        stamp = weights_stamp(picked[0])
        if self._group is None or self._group[0] != stamp:
            cell = LSTMCell.of(lstm)
            head = NumpyNet.of(rest, probe=False) if cell is not None else None
            self._group = (stamp, None if head is None else (cell, head))
        return self._group[1]

    def _memory(self) -> tuple[Any, Any]:
        """The actor's memory ``(h, c)`` it acts with next."""
        return self._actor

    def _advanced(self, actor: tuple[Any, Any], row: Any) -> None:
        """Hold the actor's memory after acting on the normalized input `row`."""
        self._actor = actor
        self._seen.append(row)

    def act(self, observation: Any) -> Any:
        """The action for one raw observation; the memory then holds it."""
        if isinstance(observation, dict):
            raise ConfigError(
                "Recurrent policies here take flat (Box) observations, not Dict ones; train "
                "goal-conditioned protagonists with a feed-forward learner."
            )
        return self._step(self._normalize(np.asarray(observation))[None])[0]

    def act_batch(self, observations: Any) -> Any:
        """Refused: one memory cannot act for a batch of different episodes."""
        raise ConfigError(
            "A recurrent policy carries one episode's memory; call act() on each copy (its "
            "batch_key is None, so advgame's batched play never calls act_batch)."
        )

    def _step(self, obs: np.ndarray) -> Any:
        """``RecurrentPPO.predict``'s operations for one normalized row, advancing the memory."""
        import torch

        x = torch.as_tensor(obs)
        actions, self._actor = self._forward(x, self._actor)
        self._seen.append(x)
        return actions

    def _forward(self, x: Any, memory: tuple[Any, Any]) -> tuple[Any, tuple[Any, Any]]:
        """The actions in the box for normalized rows `x` from `memory`, and the memory after."""
        import torch

        self._prepare()
        with torch.no_grad():
            actions, memory = self.model.policy._predict(
                x,
                lstm_states=memory,
                episode_starts=torch.zeros(len(x)),
                deterministic=self.deterministic,
            )
        shape = self.model.action_space.shape
        return self._in_box(actions.cpu().numpy().reshape((-1, *shape))), memory

    # -- white-box access: the carried state, never advanced here -------------------------------
    @staticmethod
    def _expand(state: tuple[Any, Any], n: int) -> tuple[Any, Any]:
        return state[0].expand(-1, n, -1).contiguous(), state[1].expand(-1, n, -1).contiguous()

    def episode_means(self, observations: Any) -> np.ndarray:
        """The mean actions along `observations` (a tensor ``[n, obs]``) played as one episode.

        A shallow copy plays them from a zeroed memory, deterministically (torch's generator is
        left alone), so this policy's own memory is untouched. Row ``i`` is the mean at
        observation ``i`` with the memory of observations ``0 .. i-1``: what attacks that learn
        per victim key their cache with (`advgame.adversaries.whitebox.victim_fingerprint`).
        """
        import copy

        import torch

        probe = copy.copy(self)
        probe.deterministic = True
        probe.reset(None)
        rows = []
        with torch.no_grad():
            for row in observations:
                rows.append(probe.action_mean(row[None]).numpy())
                probe.act(row.numpy())
        return np.concatenate(rows)

    def hidden_state(self) -> dict[str, tuple[Any, Any]]:
        """Copies of the memory the policy acts with next: ``{"actor": (h, c), "critic": (h, c)}``.

        Each tensor is ``[layers, 1, hidden]``; the critic's is brought up to date first.
        """
        critic = self._critic_state()
        return {
            "actor": (self._actor[0].clone(), self._actor[1].clone()),
            "critic": (critic[0].clone(), critic[1].clone()),
        }

    def action_mean(self, obs: Any) -> Any:
        """The Gaussian's mean at each row of `obs`, each row with the current actor memory."""
        import torch

        x = self._features(obs)
        dist, _ = self.model.policy.get_distribution(
            x, self._expand(self._actor, len(x)), torch.zeros(len(x))
        )
        return self._gaussian(dist.distribution).mean

    def value(self, obs: Any) -> Any:
        """``V(obs)`` per row, each row with the value head's current memory."""
        import torch

        x = self._features(obs)
        state = self._expand(self._critic_state(), len(x))
        return self.model.policy.predict_values(x, state, torch.zeros(len(x))).squeeze(-1)

    def q_value(self, obs: Any, action: Any) -> Any:
        """None: a recurrent PPO has no Q critic."""
        return None

    def numpy_net(self, head: str) -> NumpyNet | None:
        """The mean (``"mean"``) or value head (``"value"``) at the memory carried now, in NumPy.

        A `NumpyNet` of normalizer, one LSTM step at the head's current memory (the actor's;
        the critic's, caught up first; none for a critic without an LSTM), MLP and output
        layer: the same function as `action_mean` or `value`, for white-box attacks to walk
        without torch. A new net for every call (the weights copied once, per weights stamp;
        only the memory's bias is computed), so ask again after the memory moves. None where
        not covered (`advgame.core.numpy_lstm.recurrent_modules`; more than one LSTM layer).

        Unlike torch's `value` of a shared LSTM (sb3-contrib detaches the value's LSTM
        output), its input gradient is the value's true gradient.
        """
        picked = recurrent_modules(self.model.policy, head)
        if picked is None:
            return None
        modules, memory = picked
        net = self._numpy.get(head, modules, self._norm_stats())
        if net is None or memory is None:
            return net
        h, c = self._actor if memory == "actor" else self._critic_state()
        return net.at_memory(h.numpy().reshape(-1), c.numpy().reshape(-1))

    def _critic_state(self) -> tuple[Any, Any]:
        """The value head's memory now: it catches up on the inputs seen since it last did."""
        import torch

        policy = self.model.policy
        if policy.shared_lstm:
            return self._actor
        if policy.lstm_critic is None or self._critic_at == len(self._seen):
            return self._critic
        from stable_baselines3.common.policies import BaseModel

        rows = torch.cat(self._seen[self._critic_at :])
        with torch.no_grad():  # BaseModel's: what RecurrentActorCriticPolicy.predict_values runs
            features = BaseModel.extract_features(policy, rows, policy.vf_features_extractor)
            _, self._critic = policy.lstm_critic(features[:, None, :], self._critic)
        self._critic_at = len(self._seen)
        return self._critic
