"""PA-AD: a learned director picks where to push the policy, a white-box actor pushes it there.

Sun et al. (ICLR 2022, "Who Is the Strongest Enemy? Towards Optimal and Efficient Evasion
Attacks in Deep RL") split the optimal observation attack in two. The *director* is an RL
policy whose action is a direction ``d`` in the victim's **action** space (3 numbers for
Hopper where an attack learned in observation space, ATLA's optimal attack, needs 11); the
*actor* is a white-box step that finds the perturbation in the budget moving the victim's
action furthest that way::

    ŝ = argmax_{ŝ ∈ B_ε(s)} ⟨μ(ŝ) − μ(s), d / ‖d‖⟩

by the same projected gradient ascent as `MADAttack` (through the victim's NumPy network where it
has one): the outermost action the budget can reach in the direction ``d``, where PA-AD's
analysis places the optimal attack. (The paper's actor maximises the alignment of the action
change with ``d``; the cosine alone is as high for a vanishing change as for the largest, so
here the change's component along ``d`` is what the walk maximises.) The director is trained by PPO against the frozen victim, zero-sum, on the true state
the observation adversary observes; its smaller action space is why it learns the strongest
attacks of the paper's comparison in fewer steps.

Here `PAADAttack` is an ordinary white-box attack spec (``attack:pa-ad`` in tables,
``"pa-ad"`` in `advgame.adversaries.specs`). Like `RobustSarsaAttack` it learns per victim:
attaching it to a protagonist policy trains a director for it (``director_steps`` of PPO in
the attack's own threat model, `DirectorEnv`) or loads one from a cache folder, keyed by a
fingerprint of the policy, the scenario, the disruptor and the attack's settings. Evaluation
attaches every column to every row once in the main process before any job runs, so a table
trains each director once and its workers load it.

A recurrent victim (an LSTM policy) is walked with the memory it carries at each step, as every
white-box attack walks it; the director trains in views that reset that memory at each episode
start and advance it on the perturbed observations, and its cache key probes the memory too
(`advgame.adversaries.whitebox.victim_fingerprint`). The director itself sees the true state
only (a feed-forward PPO), where ATLA's learned attack on an LSTM agent is an LSTM.
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from advgame.adversaries.paad_director import director_info, train_director
from advgame.adversaries.whitebox import _Attack, cache_root, victim_fingerprint
from advgame.adversaries.whitebox_walk import NumpyScorer, WhiteBoxAttackPolicy
from advgame.core.policy import WhiteBox, act_batch, as_policy, numpy_net_of
from advgame.errors import ConfigError

if TYPE_CHECKING:
    import torch

    from advgame.core.game import Game

__all__ = ["PAADAttack", "default_cache_dir", "director_info"]

log = logging.getLogger(__name__)
_DIRECTORS: dict[str, Any] = {}
"""Directors trained or loaded in this process (their checkpoint specs), by key."""
_TINY = 1e-8
"""Added to a direction's norm, so that a zero direction scores every perturbation 0."""


def default_cache_dir() -> Path:
    """``$ADVGAME_CACHE/paad``, else ``~/.cache/advgame/paad``."""
    return cache_root() / "paad"


@dataclass(frozen=True, kw_only=True)
class PAADAttack(_Attack):
    """PA-AD (Sun et al. 2022): a learned director's action-space direction, a PGD actor.

    The `_Attack` options (``steps``, ``step_size``, ``restarts``) set the actor's walk; the
    others the director's training (PPO, the learner's defaults otherwise).

    Example:
        >>> attack = PAADAttack(director_steps=50_000)
        >>> attack.steps, attack.director_steps
        (10, 50000)

    """

    director_steps: int = 200_000
    """Environment steps the director trains against each victim (PPO with rollouts of 2,048
    steps, or of ``director_steps`` when fewer; ATLA's optimal attack here: 4 candidates of
    200k)."""
    learning_rate: float = 3e-4
    """The director's PPO learning rate."""
    ent_coef: float = 0.0
    """The director's PPO entropy bonus."""
    seed: int = 0
    """Seeds the director's training (its model, its games and the actor's random starts)."""
    cache_dir: str | None = None
    """Where trained directors are kept (default `default_cache_dir`)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if type(self.director_steps) is not int or self.director_steps < 1:
            raise ConfigError(
                f"PAADAttack.director_steps must be an int >= 1, got {self.director_steps!r}."
            )
        for name in ("learning_rate", "ent_coef"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
                raise ConfigError(f"PAADAttack.{name} must be a finite number >= 0, got {value!r}.")
        if self.learning_rate == 0:
            raise ConfigError("PAADAttack.learning_rate must be > 0.")

    # -- the actor ----------------------------------------------------------------------
    def row_objective(self, victim: WhiteBox, clean: Any, attacked: Any) -> Any:
        """PA-AD's objective needs each row's direction: see `direction_row_scorer`."""
        raise ConfigError(
            "PAADAttack scores rows against the director's directions; play it through a "
            "game (advgame.rollout / evaluation), which asks its director first."
        )

    def direction_row_scorer(
        self, victim: WhiteBox, clean: torch.Tensor, directions: np.ndarray
    ) -> Callable[[torch.Tensor], torch.Tensor]:
        """Attacked rows -> ``⟨μ(ŝ) − μ(s), d / ‖d‖⟩`` per row, in torch (differentiable)."""
        import torch

        with torch.no_grad():
            reference = victim.action_mean(clean)
        unit = torch.as_tensor(_unit(directions), dtype=reference.dtype)
        return lambda attacked: ((victim.action_mean(attacked) - reference) * unit).sum(-1)

    def direction_scorer(
        self, victim: WhiteBox, clean: np.ndarray, directions: np.ndarray
    ) -> NumpyScorer | None:
        """`direction_row_scorer` and its gradient through the victim's `NumpyNet` (or None)."""
        net = numpy_net_of(victim, "mean")
        if net is None:
            return None
        reference = net.forward(clean)[0]
        unit = _unit(directions).astype(reference.dtype)
        grad_out = np.ascontiguousarray(unit)

        def score(attacked: np.ndarray) -> tuple[np.ndarray, Callable[[], np.ndarray]]:
            mean, tape = net.forward(attacked)
            return ((mean - reference) * unit).sum(-1), lambda: net.backward(tape, grad_out)

        return score

    def build(self, info: Any) -> WhiteBoxAttackPolicy:
        """The attack for observation adversary `info.agent`; attaching it gets its director."""
        return _PAADPolicy(self, info)

    # -- the director -------------------------------------------------------------------
    def director(self, game: Game, agent: str, target: str, victim: WhiteBox) -> Any:
        """The director spec of `victim` playing `target`: from this process, the cache, or trained.

        Training plays `agent`'s observation disruptor of `game` (its spec, budget and phase) in
        `game`'s scenario against `victim` for ``director_steps`` steps
        (`advgame.adversaries.paad_director.train_director`); the result is written
        under the cache folder and returned as an `SB3Checkpoint`.
        """
        from advgame.agents.common.checkpoint import SB3Checkpoint

        key, folder = self._cached(game, agent, target, victim)
        if key not in _DIRECTORS:
            model, norm = folder / f"{agent}.zip", folder / f"{agent}_obs_norm.npz"
            if not model.is_file():
                log.info(
                    "PA-AD: training a director against %r (%d steps)", target, self.director_steps
                )
                plays = game.disruptors[agent].spec
                part = folder.with_name(f"{folder.name}.part-{os.getpid()}")
                train_director(
                    self, game.scenario_id, plays, agent, target, victim, part, phase=game.phase
                )
                try:  # in place at once: a worker training the same director may finish first
                    part.replace(folder)
                except OSError:
                    shutil.rmtree(part, ignore_errors=True)
            _DIRECTORS[key] = SB3Checkpoint(
                str(model), "ppo", str(norm) if norm.is_file() else None, deterministic=True
            )
        return _DIRECTORS[key]

    def _cached(self, game: Game, agent: str, target: str, victim: WhiteBox) -> tuple[str, Path]:
        """The director's key (policy fingerprint, scenario, disruptor, settings) and folder."""
        disruptor = game.disruptors[agent]
        size = int(np.prod(game.observation_space(target).shape or ()))
        parts = victim_fingerprint(victim, size)
        settings = repr(sorted((k, v) for k, v in asdict(self).items() if k != "cache_dir"))
        std = getattr(victim, "observation_std", None)
        parts.append(b"" if std is None else np.asarray(std, np.float64).tobytes())
        text = f"{game.scenario_id}|{agent}|{target}|{disruptor.spec!r}|{game.phase}|{settings}|"
        key = hashlib.sha256(text.encode() + b"|".join(parts)).hexdigest()[:24]
        root = Path(self.cache_dir) if self.cache_dir else default_cache_dir()
        return key, root / f"{game.scenario_id or 'game'}-{key}"

    def learned(self, game: Game, agent: str, victims: Mapping[str, Any]) -> bool:
        """Whether the director against `victims` is ready (in this process or the cache).

        With `learn`, what `advgame.evaluation.table.applicable.learn_ahead` asks to train the
        directors of a table on the executor's workers, in parallel, before the table.
        """
        targets = list(getattr(game.disruptors.get(agent), "targets", ()))
        victim = victims.get(targets[0]) if len(targets) == 1 else None
        if not isinstance(victim, WhiteBox) or len(game.protagonists) != 1:
            return True  # nothing to learn: `unplayable` will say why
        key, folder = self._cached(game, agent, targets[0], victim)
        return key in _DIRECTORS or (folder / f"{agent}.zip").is_file()


def _unit(directions: np.ndarray) -> np.ndarray:
    """Each row of `directions` scaled to length 1 (a zero row stays zero)."""
    d = np.asarray(directions, dtype=np.float64)
    return d / (np.linalg.norm(d, axis=-1, keepdims=True) + _TINY)


class _PAADPolicy(WhiteBoxAttackPolicy):
    """A built `PAADAttack`: its director picks each row's direction, the walk follows it."""

    spec: PAADAttack

    def __init__(self, spec: PAADAttack, info: Any) -> None:
        super().__init__(spec, info)
        self.direction: np.ndarray | None = None
        """This game's direction for the next walk (the director's action, or a trainer's)."""
        self.director: Any = None
        """The director's policy (after `attach`)."""

    def attach(self, game: Game, victims: Mapping[str, Any]) -> None:
        """Check the victim as every white-box attack does, then get (or train) its director."""
        if len(self.disruptor.targets) != 1 or len(game.protagonists) != 1:
            raise ConfigError(
                "PAADAttack trains a director against one protagonist, but this disruptor "
                f"targets {list(self.disruptor.targets)} of the team {list(game.protagonists)}; "
                "use MADAttack for teams."
            )
        if not game.scenario_id:
            raise ConfigError(
                "PAADAttack trains its director in the game's registered scenario; make the "
                "game with advgame.make(...)."
            )
        super().attach(game, victims)
        (target,) = self.disruptor.targets
        spec = self.spec.director(game, self.agent, target, self.victims[target])
        self.director = as_policy(spec, director_info(game, self.agent, target))

    def reset(self, seed: int | None = None) -> None:
        """Reseed the random starts (and the director, if it samples)."""
        super().reset(seed)
        if self.director is not None:
            self.director.reset(seed)

    @staticmethod
    def act_group(policies: Sequence[WhiteBoxAttackPolicy], observations: Any) -> np.ndarray:
        """Ask the directors for every game's direction (one batch), then walk towards them."""
        directors = [getattr(p, "director", None) for p in policies]
        if any(d is None for d in directors):
            raise ConfigError(
                "PAADAttack was not attached to a game; play it through advgame.rollout / "
                "evaluation (build_policies attaches it and gets its director)."
            )
        directions = act_batch(directors, list(observations))
        for pol, d in zip(policies, directions, strict=True):
            pol.direction = np.asarray(d, dtype=np.float64).reshape(-1)
        return WhiteBoxAttackPolicy.act_group(policies, observations)

    def _numpy_scorer(
        self, policies: Sequence[WhiteBoxAttackPolicy], victim: Any, clean: np.ndarray
    ) -> NumpyScorer | None:
        return self.spec.direction_scorer(victim, clean, _directions(policies))

    def _scorer(
        self, victim: Any, clean: Any, policies: Sequence[WhiteBoxAttackPolicy] = ()
    ) -> Callable[[Any], Any]:
        return self.spec.direction_row_scorer(victim, clean, _directions(policies))


def _directions(policies: Sequence[WhiteBoxAttackPolicy]) -> np.ndarray:
    """The rows' directions ``[N, act]`` (each policy's `_PAADPolicy.direction`)."""
    rows = [getattr(p, "direction", None) for p in policies]
    if any(r is None for r in rows):
        raise ConfigError("PAADAttack walked before its director (or trainer) gave a direction.")
    return np.stack(rows)  # type: ignore[arg-type]
