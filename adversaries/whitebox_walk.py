"""The built white-box attack: projected gradient ascent on the adversary's action, batched.

`WhiteBoxAttackPolicy` is what an attack spec of `advgame.adversaries.whitebox` (`MADAttack`,
`CriticAttack`, `PGDAttack`, and the learned Robust Sarsa and PA-AD attacks) builds for one
observation adversary. It binds to the game and its victims, and in each sense move walks from
random starts inside the budget: every game of one `batch_key` in one walk over ``[N, k]``,
through the victim's `NumpyNet` where there is one (no torch per step), else through torch's
autograd. The spec says what the walk maximises; this module says how it walks.

A recurrent victim (an LSTM policy, `advgame.agents.common.recurrent_policy.RecurrentSB3Policy`) is
walked with the memory it carries at the sense move of step t, before it acts on the perturbed
observation (so the perturbation of step t is computed from the memory of step t, as ATLA's
attacks are, and the victim's memory then advances on what it was shown). Its ``batch_key`` is
None, so each game walks alone, through its `NumpyNet` placed at the memory it carries now
(`advgame.core.numpy_lstm`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from advgame.core.policy import AgentInfo, WhiteBox
from advgame.disruptors.observation import ObservationRuntime
from advgame.errors import ConfigError

if TYPE_CHECKING:
    from advgame.core.game import Game

__all__ = ["AttackSpec", "NumpyScorer", "Walk", "WhiteBoxAttackPolicy"]

_RADIUS = 1.0 - 1e-6
"""L2 attacks stay this far inside the unit ball: rounding to float32 must not leave it."""

NumpyScorer = Callable[[np.ndarray], tuple[np.ndarray, Callable[[], np.ndarray]]]
"""Attacked rows ``[N, n]`` -> (the objective per row ``[N]``, a function giving its gradient)."""

Walk = Callable[[np.ndarray], tuple[np.ndarray, Callable[[], np.ndarray]]]
"""The adversary's actions ``[N, k]`` -> (objective per row, float64; its gradient in them)."""


class AttackSpec(Protocol):
    """What the walk needs of an attack spec (the specs of `advgame.adversaries.whitebox`)."""

    steps: int
    """Gradient steps per walk."""
    step_size: float | None
    """The step in the unit box (None: 2.5 / steps)."""
    restarts: int
    """Extra random starts; the best walk wins."""
    rowwise: bool
    """Whether the objective is one value per game row (games of a batch walk together)."""

    def check_victim(self, agent: str, victim: WhiteBox, probe: Any) -> None:
        """Refuse a victim the attack cannot use, with a clear message."""
        ...

    def objective(self, victim: WhiteBox, clean: Any, attacked: Any) -> Any:
        """What the walk maximises, from the clean and attacked observations (torch)."""
        ...

    def row_scorer(self, victim: WhiteBox, clean: Any) -> Callable[[Any], Any]:
        """The objective per row of a batch (torch)."""
        ...

    def numpy_scorer(self, victim: WhiteBox, clean: np.ndarray) -> NumpyScorer | None:
        """The objective and its gradient through NumPy (None: walk in torch)."""
        ...


class WhiteBoxAttackPolicy:
    """A built white-box attack: one `AttackSpec` against its disruptor's targets."""

    def __init__(self, spec: AttackSpec, info: AgentInfo) -> None:
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
                    "SB3 checkpoints (advgame.agents.common.checkpoint.SB3Checkpoint/SB3Policy) and MAPPO/IPPO "
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
            if self.disruptor.timing == "stale" and getattr(victim, "recurrent", False):
                raise ConfigError(
                    f"{type(self.spec).__name__} on {self.agent!r} has timing='stale': it moves "
                    f"with {target!r}, whose policy is recurrent, so the memory the walk reads "
                    "would depend on which of the two is asked first. Attack a recurrent policy "
                    "with timing='sense' (the faithful order)."
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
        """The spec's `AttackSpec.numpy_scorer` for the rows of `policies` (None: walk in torch).

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
