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
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from advgame.core.policy import AgentInfo, WhiteBox, numpy_net_of
from advgame.disruptors.observation import ObservationRuntime
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

_RADIUS = 1.0 - 1e-6
"""L2 attacks stay this far inside the unit ball: rounding to float32 must not leave it."""

Objective = Callable[[WhiteBox, "torch.Tensor", "torch.Tensor"], "torch.Tensor"]
"""``(victim, true observations [1, n], perturbed observations [1, n]) -> scalar to maximise``."""

NumpyScorer = Callable[[np.ndarray], tuple[np.ndarray, Callable[[], np.ndarray]]]
"""Attacked rows ``[N, n]`` -> (the objective per row ``[N]``, a function giving its gradient)."""

Walk = Callable[[np.ndarray], tuple[np.ndarray, Callable[[], np.ndarray]]]
"""The adversary's actions ``[N, k]`` -> (objective per row, float64; its gradient in them)."""


def cache_root() -> Path:
    """Where attacks keep what they learn per victim: ``$ADVGAME_CACHE``, else ``~/.cache/advgame``."""
    return Path(os.environ.get("ADVGAME_CACHE") or Path.home() / ".cache" / "advgame")


def victim_fingerprint(victim: WhiteBox, size: int) -> list[bytes]:
    """The victim's mean actions on fixed probe observations of `size`, and its action std.

    What attacks that learn per victim (Robust Sarsa's critic, PA-AD's director) key their
    cache with: two policies with these equal act alike on the probes.
    """
    import torch

    from advgame.adversaries.sarsa_critic import probe_observations

    with torch.no_grad():
        actions = victim.action_mean(probe_observations(size)).numpy().tobytes()
        std = victim.action_std()
    return [actions, b"" if std is None else std.numpy().tobytes()]


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
        define, what `advgame.evaluation.applicable.learn_ahead` runs on a table's workers.
        """
        self.build(game.agent_info(agent)).attach(game, victims)

    def unplayable(self, game: Game, agent: str, victims: Mapping[str, Any]) -> str | None:
        """Why this attack cannot play `agent` of `game` against `victims`, or None if it can.

        What `advgame.evaluation.applicable` asks before a table runs: the attack is built and
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


class WhiteBoxAttackPolicy:
    """A built white-box attack: one `_Attack` spec against its disruptor's targets."""

    def __init__(self, spec: _Attack, info: AgentInfo) -> None:
        d = info.disruptor
        if not isinstance(d, ObservationRuntime):
            kind = None if d is None else type(d.spec).__name__
            raise ConfigError(
                f"{type(spec).__name__} attacks observations; {info.agent!r} controls {kind}. "
                "Give it to an ObservationDisruptor's adversary (e.g. 'observation_adversary')."
            )
        if not d.bounded:
            raise ConfigError(
                f"{type(spec).__name__} needs a budget, but {info.agent!r}'s ObservationDisruptor "
                "is unbounded (bounded=False, the paper's random mode); give it eps=..."
            )
        self.spec, self.disruptor, self.agent = spec, d, info.agent
        self.alpha = spec.step_size if spec.step_size is not None else 2.5 / spec.steps
        self.rng = np.random.default_rng()
        self.game: Game | None = None
        self.victims: dict[str, WhiteBox] = {}

    def attach(self, game: Game, victims: Mapping[str, Any]) -> None:
        """Bind to the game and the protagonist policies of the disruptor's targets."""
        import torch

        for target in self.disruptor.targets:
            victim = victims.get(target)
            if not isinstance(victim, WhiteBox):
                raise ConfigError(
                    f"{type(self.spec).__name__} on {self.agent!r} needs white-box access to "
                    f"{target!r}'s policy, but it is {type(victim).__name__}. White-box policies: "
                    "SB3 checkpoints (advgame.training.checkpoint.SB3Checkpoint/SB3Policy) and MAPPO/IPPO "
                    "actors; a learner being trained inside a view cannot be attacked this way."
                )
            space = self.disruptor.spaces.get(target)  # Box targets only; Dicts have plans
            if space is None:
                raise ConfigError(
                    f"{type(self.spec).__name__} on {self.agent!r} attacks a Box observation, but "
                    f"{target!r} observes a Dict. White-box attacks do not cover Dict "
                    "observations (goal-conditioned tasks); use random, scheduled or learned "
                    "observation adversaries there."
                )
            n = int(np.prod(space.shape))
            with torch.no_grad():
                self.spec.check_victim(target, victim, torch.zeros((1, n)))
            self.victims[target] = victim
        self.game = game

    def reset(self, seed: int | None = None) -> None:
        """Reseed the random starts."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    @property
    def batch_key(self) -> tuple | None:
        """Equal for attacks that one batched walk may serve (`act_group`), else None.

        The same attack spec on the same disruptor layout, against victims that are copies of
        one frozen network (equal ``batch_key``s): then every game's rows go through one
        projected-gradient walk over ``[N, k]``. A user's `PGDAttack` objective is one scalar,
        so each game then attacks alone.
        """
        if not self.spec.rowwise or self.game is None:
            return None
        d = self.disruptor
        keys = tuple(getattr(self.victims.get(t), "batch_key", None) for t in d.targets)
        if any(k is None for k in keys):
            return None
        return ("whitebox", self.spec, tuple(d.targets), d.norm, keys)

    def act(self, observation: Any) -> np.ndarray:
        """Attack every target's true observation; return the adversary action ``u``."""
        return self.act_group([self], [observation])[0]

    @staticmethod
    def act_group(policies: Sequence[WhiteBoxAttackPolicy], observations: Any) -> np.ndarray:
        """The actions of several attacks of one `batch_key` (one game each), in one walk.

        Row ``i`` is what ``policies[i].act`` plays alone: its random starts come from its own
        generator in the same order, and every row's steps, projections and best iterate are
        computed row by row in the same float64 arithmetic; only the network passes are shared.
        """
        for pol in policies:
            if pol.game is None:
                raise ConfigError(
                    f"{type(pol.spec).__name__} was not attached to a game; play it through "
                    "advgame.rollout / evaluation (build_policies attaches it)."
                )
        head = policies[0]
        blocks = [head._attack_rows(policies, t) for t in head.disruptor.targets]
        return np.concatenate(blocks, axis=1).astype(np.float32)

    def objective_of(self, target: str, u: np.ndarray) -> float:
        """The attack's objective at action block `u` for `target` (for tests and reports)."""
        import torch

        clean, perturb = self._problem([self], target)
        with torch.enable_grad():  # objectives may differentiate internally (e.g. a critic's)
            u_t = torch.as_tensor(np.asarray(u, dtype=np.float32).reshape(1, -1))
            return float(self.spec.objective(self.victims[target], clean, perturb(u_t)).detach())

    def _rows(self, policies: Sequence[WhiteBoxAttackPolicy], target: str) -> tuple[Any, ...]:
        """What every walk on `target` needs, for the games of `policies`, in float32 NumPy.

        The clean observation rows ``[N, n]`` of each game; where the adversary's block ``u``
        (``[N, k]``) lands (`index`) and its scale there (that game's current ε ⊙ normalizer
        scale); and the observation space's bounds, into which the game clips perturbed rows.
        """
        d = self.disruptor
        start = sum(d.dims[t].size for t in d.targets[: d.targets.index(target)])
        stop = start + d.dims[target].size
        space = d.spaces[target]
        rows = []
        for pol in policies:
            assert pol.game is not None  # act_group checked
            rows.append(np.asarray(pol.game.true_observation(target), dtype=np.float32).reshape(-1))
        scale = np.stack([pol.disruptor.unit[start:stop] for pol in policies]).astype(np.float32)
        low = space.low.reshape(-1).astype(np.float32)
        high = space.high.reshape(-1).astype(np.float32)
        return np.stack(rows), np.asarray(d.dims[target]), scale, low, high

    def _problem(
        self, policies: Sequence[WhiteBoxAttackPolicy], target: str, rows: tuple | None = None
    ) -> tuple[Any, Any]:
        """The clean rows ``[N, n]`` (torch) of `target` in each game, and ``u -> perturbed``.

        The perturbed observations are the clean ones plus ``scale ⊙ u`` at `index`, clipped
        into the observation space, as the game clips them (`_rows`, unless given as `rows`).
        """
        import torch

        if rows is None:
            rows = self._rows(policies, target)
        clean_np, index_np, scale_np, low_np, high_np = rows
        clean, scale = torch.as_tensor(clean_np), torch.as_tensor(scale_np)
        index = torch.as_tensor(index_np, dtype=torch.long)
        low, high = torch.as_tensor(low_np), torch.as_tensor(high_np)

        def perturb(u: torch.Tensor) -> torch.Tensor:
            delta = torch.zeros_like(clean).index_add(1, index, scale * u)
            return torch.maximum(torch.minimum(clean + delta, high), low)

        return clean, perturb

    def _walk(self, policies: Sequence[WhiteBoxAttackPolicy], target: str) -> Walk:
        """The objective of every game's row, and its gradient, as functions of ``u``.

        Through the victim's `NumpyNet` where the attack and the victim have one (no torch
        per step), else through torch's autograd (`_torch_walk`).
        """
        victim = self.victims[target]
        rows = self._rows(policies, target)
        clean, index, scale, low, high = rows
        scorer = self._numpy_scorer(policies, victim, clean)
        if scorer is None:
            return self._torch_walk(policies, target, rows)
        clipped = bool(np.isfinite(low).any() or np.isfinite(high).any())

        def walk(u: np.ndarray) -> tuple[np.ndarray, Callable[[], np.ndarray]]:
            x = clean.copy()
            x[:, index] += scale * u.astype(np.float32)
            inside = None
            if clipped:
                inside = (x > low) & (x < high)
                x = np.maximum(np.minimum(x, high), low)
            values, grad_x = scorer(x)

            def grad() -> np.ndarray:
                g = grad_x()
                if inside is not None:
                    g = g * inside
                return g[:, index] * scale

            return values.astype(np.float64), grad

        return walk

    def _torch_walk(
        self, policies: Sequence[WhiteBoxAttackPolicy], target: str, rows: tuple | None = None
    ) -> Walk:
        """`_walk` through torch: a graph per step, the gradient by autograd."""
        import torch

        clean, perturb = self._problem(policies, target, rows)
        with torch.enable_grad():
            score = self._scorer(self.victims[target], clean, policies)

        def walk(u: np.ndarray) -> tuple[np.ndarray, Callable[[], np.ndarray]]:
            with torch.enable_grad():  # objectives may differentiate internally (a critic's)
                u_t = torch.as_tensor(u, dtype=torch.float32).requires_grad_(True)
                values = score(perturb(u_t))

            def grad() -> np.ndarray:
                return torch.autograd.grad(values.sum(), u_t)[0].numpy()

            return values.detach().numpy().astype(np.float64), grad

        return walk

    def _attack_rows(self, policies: Sequence[WhiteBoxAttackPolicy], target: str) -> np.ndarray:
        """Projected gradient ascent from random starts for every game; each row's best iterate."""
        size, n = self.disruptor.dims[target].size, len(policies)
        walk = self._walk(policies, target)
        best_u, best = np.zeros((n, size)), np.full(n, -np.inf)
        for _ in range(1 + self.spec.restarts):
            u = self._project(np.stack([p.rng.uniform(-1.0, 1.0, size) for p in policies]))
            for step in range(self.spec.steps + 1):
                scores, grad = walk(u)
                better = scores > best
                best_u[better], best[better] = u[better], scores[better]
                if step == self.spec.steps:
                    break
                u = self._project(u + self.alpha * self._direction(grad()))
        return best_u

    def _numpy_scorer(
        self, policies: Sequence[WhiteBoxAttackPolicy], victim: Any, clean: np.ndarray
    ) -> NumpyScorer | None:
        """The spec's `_Attack.numpy_scorer` for the rows of `policies` (None: walk in torch).

        A hook for attacks whose objective also depends on each game's own state (PA-AD's
        direction per row).
        """
        return self.spec.numpy_scorer(victim, clean) if self.spec.rowwise else None

    def _scorer(
        self, victim: Any, clean: Any, policies: Sequence[WhiteBoxAttackPolicy] = ()
    ) -> Callable[[Any], Any]:
        """Attacked rows -> the objective per row (``[N]``), for the rows of `policies`.

        An attack scored as one scalar plays one row.
        """
        if self.spec.rowwise:
            return self.spec.row_scorer(victim, clean)
        return lambda attacked: self.spec.objective(victim, clean, attacked).reshape(1)

    def _direction(self, grad: np.ndarray) -> np.ndarray:
        """Steepest ascent for the ball, per row: the gradient's sign (L∞) or direction (L2)."""
        if self.disruptor.norm == "linf":
            return np.sign(grad)
        out = grad.astype(np.float64)
        for i, row in enumerate(grad):  # row by row: the norm a lone game computes
            norm = float(np.linalg.norm(row))
            out[i] = row / norm if norm > 0 else row
        return out

    def _project(self, u: np.ndarray) -> np.ndarray:
        """Each row onto the adversary's budget: the unit box (L∞) or the unit ball (L2)."""
        u = np.clip(u, -1.0, 1.0)
        if self.disruptor.norm == "l2":
            for i, row in enumerate(u):
                norm = float(np.linalg.norm(row))
                if norm > _RADIUS:  # a hair inside, so the float32 action stays in the ball
                    u[i] = row * (_RADIUS / norm)
        return u
