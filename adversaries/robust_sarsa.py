"""The Robust Sarsa (RS) attack: learn the frozen protagonist's own ``Q^π``, then attack it.

Zhang et al. 2020 ("Robust Deep RL against Adversarial Perturbations on State Observations",
section 6 and appendix) judge a policy under the strongest of several attacks; RS is the one
that needs neither the policy's critic nor a trained adversary. It first learns ``Q^π(s, a)``
of the fixed policy on-policy (Sarsa: the TD target uses the action the policy really takes
next), with a robustness term that keeps ``Q`` smooth in the action, so that its gradient
through ``π(ŝ)`` points somewhere useful::

    L(φ) = E[(r + γ (1 - done) Q_φ̄(s', π(s')) - Q_φ(s, a))²]
           + λ_RS E[max_{â ∈ B_ε(a)} (Q_φ(s, â) - Q_φ(s, a))²]

(the inner max by a few signed-gradient steps in an L∞ ball of ``ε_RS`` times the action
range). The attack then runs the same projected gradient ascent as `MADAttack` on the
perturbation, minimising ``Q(s, π(s + δ))``: the true state valued under the action the
perturbation induces.

Learning ``Q^π`` costs simulator steps and a few seconds of fitting, so it happens once per
protagonist: attaching the attack to a victim learns it, or loads it from a cache folder where
it is stored under a fingerprint of the policy (its mean actions on fixed probe observations),
the scenario and the attack's settings. `advgame.evaluation.evaluate` asks every column about
every row in the main process before any job runs (`advgame.evaluation.table.applicable`), which
attaches the attack once per protagonist: the critic is learned there, once, and every worker
and episode loads it.

A recurrent victim (an LSTM policy) plays the data collection with its memory (reset at each
episode start, advanced at every step, ``μ`` read with the memory of that step), and the attack
walks ``π(s + δ)`` with the memory it carries at the attacked step. ``Q^π(s, a)`` itself sees
the true state only, as the MLP critic of ATLA's Robust Sarsa on its LSTM agents does.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from advgame.adversaries.whitebox import _Attack, cache_root, victim_fingerprint
from advgame.adversaries.whitebox_walk import NumpyScorer, WhiteBoxAttackPolicy
from advgame.core.policy import WhiteBox, numpy_net_of
from advgame.errors import ConfigError

if TYPE_CHECKING:
    import torch

    from advgame.core.game import Game

__all__ = ["MaxCostAttack", "RobustSarsaAttack", "default_cache_dir"]

log = logging.getLogger(__name__)
_CRITICS: dict[str, Any] = {}
"""Critics learned or loaded in this process, by key (scenario, target, settings, policy)."""


def default_cache_dir() -> Path:
    """``$ADVGAME_CACHE/robust_sarsa``, else ``~/.cache/advgame/robust_sarsa``."""
    return cache_root() / "robust_sarsa"


@dataclass(frozen=True, kw_only=True)
class RobustSarsaAttack(_Attack):
    """Minimise a learned ``Q^π(s, π(s + δ))`` of the frozen protagonist (Robust Sarsa).

    Example:
        >>> attack = RobustSarsaAttack(samples=20_000, reg=0.1)
        >>> attack.steps, attack.samples
        (10, 20000)

    """

    samples: int = 20_000
    """Environment steps of the protagonist (nominal game, its deterministic actions) that
    ``Q^π`` is fitted on."""
    epochs: int = 30
    """Passes of TD fitting over the samples."""
    batch_size: int = 256
    """Transitions per gradient step."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layer widths of the Q network (tanh)."""
    gamma: float = 0.99
    """Discount of ``Q^π``."""
    lr: float = 1e-3
    """Adam learning rate."""
    reg: float = 0.1
    """λ_RS, the weight of the action-robustness term (0: plain Sarsa)."""
    reg_eps: float = 0.05
    """ε_RS: the L∞ radius of the action ball, as a fraction of each action's range."""
    reg_steps: int = 5
    """Signed-gradient steps of the inner maximisation."""
    seed: int = 0
    """Seeds the data collection and the network."""
    cache_dir: str | None = None
    """Where learned critics are kept (default `default_cache_dir`)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("samples", "epochs", "batch_size", "reg_steps"):
            value = getattr(self, name)
            if type(value) is not int or value < 1:
                raise ConfigError(f"RobustSarsaAttack.{name} must be an int >= 1, got {value!r}.")
        for name, low, high in (("gamma", 0.0, 1.0), ("reg_eps", 0.0, 1.0)):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not low <= value <= high:
                raise ConfigError(
                    f"RobustSarsaAttack.{name} must be in [{low}, {high}], got {value!r}."
                )
        for name in ("lr", "reg"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
                raise ConfigError(
                    f"RobustSarsaAttack.{name} must be a finite number >= 0, got {value!r}."
                )
        if not self.hidden or not all(type(h) is int and h > 0 for h in self.hidden):
            raise ConfigError(
                f"RobustSarsaAttack.hidden must be positive ints, got {self.hidden!r}."
            )

    signal: ClassVar[str] = "reward"
    """What the learned ``Q`` sums: the reward (RS) or the true cost (`MaxCostAttack`)."""

    # -- the attack ----------------------------------------------------------------------
    def row_objective(self, victim: WhiteBox, clean: torch.Tensor, attacked: torch.Tensor) -> Any:
        """Per row, minus the learned ``Q^π(s, π(s + δ))`` (plus ``Q_c^π`` for the cost)."""
        q = _CRITICS[_key_of(victim)](clean, victim.action_mean(attacked))
        return q if self.signal == "cost" else -q

    def numpy_scorer(self, victim: WhiteBox, clean: np.ndarray) -> NumpyScorer | None:
        """`row_objective` and its gradient through NumPy copies of ``π``'s mean and ``Q^π``."""
        actor, critic = numpy_net_of(victim, "mean"), _CRITICS[_key_of(victim)]
        q_net = critic.numpy_net()
        if actor is None or q_net is None:
            return None
        stats, sign = critic.stats, np.float32(1 if self.signal == "cost" else -1)
        state = (clean - stats["obs_mean"]) / stats["obs_std"]  # the true state: fixed per walk

        def score(attacked: np.ndarray) -> tuple[np.ndarray, Callable[[], np.ndarray]]:
            action, actor_tape = actor.forward(attacked)
            x = np.concatenate([state, (action - stats["act_mean"]) / stats["act_std"]], axis=1)
            q, q_tape = q_net.forward(x)

            def grad() -> np.ndarray:
                g = q_net.backward(q_tape, np.full_like(q, sign))[:, state.shape[1] :]
                return actor.backward(actor_tape, g / stats["act_std"])

            return sign * q[:, 0], grad

        return score

    def build(self, info: Any) -> WhiteBoxAttackPolicy:
        """The attack for observation adversary `info.agent`; it learns ``Q^π`` when attached."""
        return _RobustSarsaPolicy(self, info)

    def critic(self, game: Game, target: str, victim: WhiteBox) -> Any:
        """``Q^π`` of `victim` playing `target` in `game`: from this process, the cache, or learned.

        Learning plays ``samples`` steps of `game`'s scenario (nominal) and fits the network
        (seconds to a minute); the result is written to the cache folder.
        """
        from advgame.adversaries.sarsa_critic import QNetwork, fit_sarsa

        key, path = self._cached(game, target, victim)
        _mark(victim, key)
        if key not in _CRITICS:
            if path.is_file():
                _CRITICS[key] = QNetwork.load(path)
            else:
                log.info(
                    "%s: learning Q^pi of %r's %s (%d steps)",
                    type(self).__name__, target, self.signal, self.samples,
                )  # fmt: skip
                fields = {k: v for k, v in asdict(self).items() if k in _FIT_FIELDS}
                _CRITICS[key] = fit_sarsa(
                    game.scenario_id, target, victim, signal=self.signal, **fields
                )
                _CRITICS[key].save(path)
        return _CRITICS[key]

    def _cached(self, game: Game, target: str, victim: WhiteBox) -> tuple[str, Path]:
        """The critic's key (policy fingerprint, scenario, settings) and cache file."""
        size = int(np.prod(game.observation_space(target).shape or ()))
        parts = victim_fingerprint(victim, size)
        settings = repr(sorted((k, v) for k, v in asdict(self).items() if k in _FIT_FIELDS))
        settings += "|cost" if self.signal == "cost" else ""
        text = f"{game.scenario_id}|{target}|{settings}|".encode() + b"|".join(parts)
        key = hashlib.sha256(text).hexdigest()[:24]
        root = Path(self.cache_dir) if self.cache_dir else default_cache_dir()
        return key, root / f"{game.scenario_id or 'game'}-{key}.pt"

    def learned(self, game: Game, agent: str, victims: Mapping[str, Any]) -> bool:
        """Whether every target's ``Q^π`` is ready (in this process or the cache).

        With `learn`, what `advgame.evaluation.table.applicable.learn_ahead` asks to fit the critics
        of a table on the executor's workers, in parallel, before the table.
        """
        if len(game.protagonists) != 1 or not game.scenario_id:
            return True  # nothing to learn: `unplayable` will say why
        for target in getattr(game.disruptors.get(agent), "targets", ()):
            victim = victims.get(target)
            if isinstance(victim, WhiteBox):
                key, path = self._cached(game, target, victim)
                if key not in _CRITICS and not path.is_file():
                    return False
        return True


_FIT_FIELDS: tuple[str, ...] = ("samples", "epochs", "batch_size", "hidden", "gamma", "lr")
_FIT_FIELDS += ("reg", "reg_eps", "reg_steps", "seed")


@dataclass(frozen=True, kw_only=True)
class MaxCostAttack(RobustSarsaAttack):
    """Maximise a learned cost ``Q_c^π(s, π(s + δ))`` of the frozen protagonist (safe scenarios).

    The maximum-cost (MC) attack of Liu et al. 2023 ("On the Robustness of Safe Reinforcement
    Learning under Observational Perturbations"): the perturbation that steers the policy to the
    action its cost critic values most, i.e. into the constraint, where reward-minimising
    attacks aim at the return. Liu et al. read the victim's own ``Q_c`` (an off-policy safe
    learner has one); advgame's constrained learners keep a state cost value only, so ``Q_c^π``
    is learned here as Robust Sarsa learns ``Q^π`` (the same settings and cache), on the true
    cost of the nominal game.

    Example:
        >>> MaxCostAttack(samples=20_000).signal
        'cost'

    """

    signal: ClassVar[str] = "cost"


class _RobustSarsaPolicy(WhiteBoxAttackPolicy):
    """A built `RobustSarsaAttack`: attaching it loads (or learns) each victim's ``Q^π``."""

    spec: RobustSarsaAttack

    def attach(self, game: Game, victims: Mapping[str, Any]) -> None:
        """Check the victims as every white-box attack does, then get their critics."""
        if len(game.protagonists) != 1:
            raise ConfigError(
                "RobustSarsaAttack learns one protagonist's Q^pi, but this game has the team "
                f"{list(game.protagonists)}; use MADAttack for teams."
            )
        if not game.scenario_id:
            raise ConfigError(
                "RobustSarsaAttack learns Q^pi in the game's registered scenario; make the game "
                "with advgame.make(...)."
            )
        if self.spec.signal == "cost" and not getattr(game.task, "has_cost", False):
            raise ConfigError(
                f"MaxCostAttack maximises a learned cost, but {game.scenario_id} computes no "
                "cost; use it on a safe scenario (advgame.list_scenarios(family='safe'))."
            )
        super().attach(game, victims)
        for target, victim in self.victims.items():
            self.spec.critic(game, target, victim)


def _mark(victim: Any, key: str) -> None:
    """Remember on `victim` which critic values it (`objective` sees only the victim)."""
    object.__setattr__(victim, "_robust_sarsa_key", key)


def _key_of(victim: Any) -> str:
    key = getattr(victim, "_robust_sarsa_key", None)
    if key is None or key not in _CRITICS:
        raise ConfigError("RobustSarsaAttack played a victim it was not attached to.")
    return str(key)
