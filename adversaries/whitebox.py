"""White-box observation attacks: MAD, critic and PGD on the frozen protagonist's own networks.

The robust-RL literature evaluates a policy against attacks that read its networks (Zhang et
al. 2020, "Robust Deep RL against Adversarial Perturbations on State Observations"; Pattanaik
et al. 2018): a few projected gradient steps per step, typically far stronger than noise of
the same budget and needing no training. Here each attack is an ordinary adversary spec for
an `ObservationDisruptor` agent, so it sits in payoff tables and populations like noise or a
trained network:

* `MADAttack` — maximal action difference: maximise the divergence between ``π(·|s)`` and
  ``π(·|s+δ)`` (the KL of the two Gaussians for a stochastic policy, the squared distance of
  the actions for a deterministic one);
* `CriticAttack` — minimise the protagonist's own value estimate: ``Q(s, μ(s+δ))`` for SAC/TD3
  (Pattanaik et al.), ``V(s+δ)`` for PPO;
* `PGDAttack` — maximise a user-given differentiable objective.

How it plays: `advgame.core.episodes.build_policies` attaches the attack to the game and to the
protagonist policies it attacks (each must be an `advgame.core.policy.WhiteBox`: an SB3 policy with
its normalizer, or a MAPPO/IPPO actor). In the sense move the attack reads each target's true
observation ``s_t`` and runs projected gradient ascent on the adversary's own action ``u``:
inside ``[-1, 1]^k`` (L∞) or each target's unit ball (L2), which the disruptor maps to
``δ = ε ⊙ u`` in raw or normalized units. So the attack is in the budget by construction, and
the disruptor still clips and counts. Gradients are taken with respect to ``u`` only
(`torch.autograd.grad`): the protagonist's parameters, gradients and optimizer are untouched.

This module holds the specs (what each attack maximises); the walk they all share, batched over
games, is `advgame.adversaries.whitebox_walk.WhiteBoxAttackPolicy`, which every spec builds.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from advgame.adversaries.whitebox_walk import NumpyScorer, WhiteBoxAttackPolicy
from advgame.core.policy import AgentInfo, WhiteBox, numpy_net_of
from advgame.errors import ConfigError

if TYPE_CHECKING:
    import torch

    from advgame.core.game import Game

__all__ = [
    "CriticAttack",
    "MADAttack",
    "PGDAttack",
    "WhiteBoxAttackPolicy",
    "cache_root",
    "victim_fingerprint",
]

Objective = Callable[[WhiteBox, "torch.Tensor", "torch.Tensor"], "torch.Tensor"]
"""``(victim, true observations [1, n], perturbed observations [1, n]) -> scalar to maximise``."""


def cache_root() -> Path:
    """Where attacks keep what they learn per victim: ``$ADVGAME_CACHE``, else ``~/.cache/advgame``."""
    return Path(os.environ.get("ADVGAME_CACHE") or Path.home() / ".cache" / "advgame")


def victim_fingerprint(victim: WhiteBox, size: int) -> list[bytes]:
    """The victim's mean actions on fixed probe observations of `size`, and its action std.

    What attacks that learn per victim (Robust Sarsa's critic, PA-AD's director) key their
    cache with: two policies with these equal act alike on the probes. A recurrent victim (one
    with ``recurrent = True``: its action depends on its memory) is probed along the probes
    played as one episode from a zeroed memory (`_recurrent_probe`), so the key covers how its
    memory moves, does not depend on where in an episode it is asked, and is tagged so that it
    never equals a feed-forward policy's.
    """
    import torch

    from advgame.adversaries.sarsa_critic import probe_observations

    probes = probe_observations(size)
    with torch.no_grad():
        std = victim.action_std()
        if getattr(victim, "recurrent", False):
            head, actions = [b"recurrent"], _recurrent_probe(victim, probes)
        else:
            head, actions = [], victim.action_mean(probes).numpy().tobytes()
    return [*head, actions, b"" if std is None else std.numpy().tobytes()]


def _recurrent_probe(victim: Any, probes: torch.Tensor) -> bytes:
    """The mean actions of a recurrent victim along `probes` played in order from a zero memory.

    (`advgame.agents.common.recurrent_policy.RecurrentSB3Policy.episode_means`: the victim's own memory
    is untouched.)
    """
    inner = victim
    while getattr(type(inner), "wrapped", None) is not None:  # a mixture: its member now
        inner = inner.wrapped
    return inner.episode_means(probes).tobytes()


@dataclass(frozen=True, kw_only=True)
class _Attack:
    """Projected gradient ascent on the adversary's action; the options every attack shares.

    Each walk starts uniformly at random in the budget and takes `steps` projected steps; the
    best iterate of all walks (by the attack's objective) is played.
    """

    steps: int = 10
    """Gradient steps per attacked step (SA-PPO's evaluation uses 10)."""
    step_size: float | None = None
    """Step length in the adversary's action units (the budget is 1); default ``2.5 / steps``
    (Madry et al.'s rule: the walk can cross the ball 2.5 times)."""
    restarts: int = 0
    """Extra random starts; the start reaching the highest objective is played."""

    def __post_init__(self) -> None:
        if type(self.steps) is not int or self.steps < 1:
            raise ConfigError(
                f"{type(self).__name__}.steps must be an int >= 1, got {self.steps!r}."
            )
        if type(self.restarts) is not int or self.restarts < 0:
            raise ConfigError(
                f"{type(self).__name__}.restarts must be an int >= 0, got {self.restarts!r}."
            )
        if self.step_size is not None and not (np.isfinite(self.step_size) and self.step_size > 0):
            raise ConfigError(
                f"{type(self).__name__}.step_size must be a finite number > 0 (or None for "
                f"2.5 / steps), got {self.step_size!r}."
            )

    rowwise: ClassVar[bool] = True
    """Whether `row_objective` scores each row on its own (then N games attack in one batch)."""

    def row_objective(
        self, victim: WhiteBox, clean: torch.Tensor, attacked: torch.Tensor
    ) -> torch.Tensor:
        """What the attack maximises, per row of the batch (``[batch]``)."""
        raise NotImplementedError

    def row_scorer(
        self, victim: WhiteBox, clean: torch.Tensor
    ) -> Callable[[torch.Tensor], torch.Tensor]:
        """`row_objective` for one batch of clean rows, as a function of the attacked rows.

        A walk scores many attacked batches against the same clean rows; an attack with work
        that depends on the clean rows alone (MAD's reference action) does it here, once.
        """
        return lambda attacked: self.row_objective(victim, clean, attacked)

    def numpy_scorer(self, victim: WhiteBox, clean: np.ndarray) -> NumpyScorer | None:
        """`row_scorer` in NumPy, where the victim's networks have a `NumpyNet`; else None.

        The scorer maps attacked rows (float32 ``[N, obs]``) to the objective per row and a
        function giving its gradient in those rows; the walk then needs no torch at all.
        """
        return None

    def objective(self, victim: WhiteBox, clean: torch.Tensor, attacked: torch.Tensor) -> Any:
        """What the attack maximises over the batch (a scalar tensor: the rows' sum)."""
        return self.row_objective(victim, clean, attacked).sum()

    def check_victim(self, agent: str, victim: WhiteBox, probe: torch.Tensor) -> None:
        """Raise if `victim` lacks what this attack differentiates (`probe`: a zero batch)."""

    def build(self, info: AgentInfo) -> WhiteBoxAttackPolicy:
        """The attack for observation adversary `info.agent` (attached to its victims later)."""
        return WhiteBoxAttackPolicy(self, info)

    def learn(self, game: Game, agent: str, victims: Mapping[str, Any]) -> None:
        """Learn (or load) what attaching this attack to `victims` learns, as attaching does.

        With ``learned(game, agent, victims) -> bool``, which attacks that learn per victim
        define, what `advgame.evaluation.table.applicable.learn_ahead` runs on a table's workers.
        """
        self.build(game.agent_info(agent)).attach(game, victims)

    def unplayable(self, game: Game, agent: str, victims: Mapping[str, Any]) -> str | None:
        """Why this attack cannot play `agent` of `game` against `victims`, or None if it can.

        What `advgame.evaluation.table.applicable` asks before a table runs: the attack is built and
        attached as in a real episode, and the `ConfigError` its attaching would raise is the
        reason. A column that cannot work for any row (not an observation adversary, no
        budget) raises here instead.
        """
        policy = self.build(game.agent_info(agent))
        try:
            policy.attach(game, victims)
        except ConfigError as exc:
            return str(exc)
        return None


@dataclass(frozen=True, kw_only=True)
class MADAttack(_Attack):
    """Maximal action difference (Zhang et al. 2020): push ``π(·|s+δ)`` away from ``π(·|s)``.

    For a Gaussian policy with state-independent std σ (PPO, MAPPO/IPPO actors) the objective
    is ``KL(π(·|s) ‖ π(·|s+δ)) = Σ (μ(s+δ) − μ(s))² / 2σ²``; for a deterministic actor (SAC's
    mode, TD3) it is ``‖μ(s+δ) − μ(s)‖²``.

    Example:
        >>> attack = MADAttack(steps=5, restarts=2)  # 3 starts of 5 steps each, per step
        >>> attack.steps * (1 + attack.restarts)
        15

    """

    def row_objective(
        self, victim: WhiteBox, clean: torch.Tensor, attacked: torch.Tensor
    ) -> torch.Tensor:
        """Per row, the KL (or squared distance) between the clean and the attacked action."""
        return self.row_scorer(victim, clean)(attacked)

    def row_scorer(
        self, victim: WhiteBox, clean: torch.Tensor
    ) -> Callable[[torch.Tensor], torch.Tensor]:
        """`row_objective` with the clean rows' action computed once for the whole walk."""
        import torch

        with torch.no_grad():
            reference = victim.action_mean(clean)
        std = victim.action_std()

        def score(attacked: torch.Tensor) -> torch.Tensor:
            diff = victim.action_mean(attacked) - reference
            if std is None:
                return (diff * diff).sum(-1)
            return (diff * diff / (2.0 * std * std)).sum(-1)

        return score

    def numpy_scorer(self, victim: WhiteBox, clean: np.ndarray) -> NumpyScorer | None:
        """The KL (or squared distance) and its gradient through the victim's `NumpyNet`."""
        net = numpy_net_of(victim, "mean")
        if net is None:
            return None
        reference = net.forward(clean)[0]
        std = victim.action_std()
        two_var = None if std is None else (2.0 * std * std).numpy()  # as torch's path has it

        def score(attacked: np.ndarray) -> tuple[np.ndarray, Callable[[], np.ndarray]]:
            mean, tape = net.forward(attacked)
            diff = mean - reference
            if two_var is None:
                return (diff * diff).sum(-1), lambda: net.backward(tape, 2 * diff)
            return (diff * diff / two_var).sum(-1), lambda: net.backward(tape, 2 * diff / two_var)

        return score


@dataclass(frozen=True, kw_only=True)
class CriticAttack(_Attack):
    """Drive the protagonist into what its own critic calls bad (Pattanaik et al. 2018).

    With a Q critic (SAC, TD3) it minimises ``Q(s, μ(s+δ))``: the true state valued under the
    action the perturbation induces. With a value head only (PPO) it minimises ``V(s+δ)``.
    """

    def row_objective(
        self, victim: WhiteBox, clean: torch.Tensor, attacked: torch.Tensor
    ) -> torch.Tensor:
        """Per row, minus the critic's estimate."""
        q = victim.q_value(clean, victim.action_mean(attacked))
        if q is not None:
            return -q
        return -victim.value(attacked)

    def numpy_scorer(self, victim: WhiteBox, clean: np.ndarray) -> NumpyScorer | None:
        """Minus ``V`` through the victim's value `NumpyNet` (a policy without a Q critic)."""
        net = numpy_net_of(victim, "value")
        if net is None:
            return None

        def score(attacked: np.ndarray) -> tuple[np.ndarray, Callable[[], np.ndarray]]:
            value, tape = net.forward(attacked)
            return -value[:, 0], lambda: net.backward(tape, np.full_like(value, -1))

        return score

    def check_victim(self, agent: str, victim: WhiteBox, probe: torch.Tensor) -> None:
        """The victim must have a critic (SB3 policies do; MAPPO/IPPO actor files do not)."""
        with_q = victim.q_value(probe, victim.action_mean(probe)) is not None
        if not with_q and victim.value(probe) is None:
            raise ConfigError(
                f"CriticAttack needs a critic, but the policy of {agent!r} "
                f"({type(victim).__name__}) has none; use MADAttack, which needs only the actor."
            )


@dataclass(frozen=True, kw_only=True)
class PGDAttack(_Attack):
    """Projected gradient ascent on any differentiable objective you give.

    Args:
        objective_fn: ``(victim, clean, attacked) -> scalar tensor`` to maximise, where
            `victim` is the protagonist's `WhiteBox` policy and `clean`/`attacked` are raw
            observation batches ``[1, n]``. A module-level function, so the spec pickles.

    Example:
        >>> def push_first_action_up(victim, clean, attacked):
        ...     return victim.action_mean(attacked)[0, 0]
        >>> PGDAttack(objective_fn=push_first_action_up, steps=4).steps
        4

    """

    objective_fn: Objective
    rowwise: ClassVar[bool] = False  # a user's objective is one scalar: each game attacks alone

    def __post_init__(self) -> None:
        super().__post_init__()
        if not callable(self.objective_fn):
            raise ConfigError(
                f"PGDAttack.objective_fn must be callable, got {self.objective_fn!r}."
            )

    def objective(self, victim: WhiteBox, clean: torch.Tensor, attacked: torch.Tensor) -> Any:
        """The user's objective."""
        return self.objective_fn(victim, clean, attacked)
