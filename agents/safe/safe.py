"""Constrained protagonist learners: PPO-Lagrangian, CRPO and PCRPO on one PPO core.

No maintained library offers these beside gymnasium 1.x (OmniSafe pins gymnasium 0.28), so they
are written out (design invariant 6) on the MAPPO/IPPO machinery (`advgame.agents.marl.marl`): the
same views, normalizers, actors and checkpoints, plus a cost critic (`advgame.agents.safe.ppo`).
The learner sees only the cost it *observes* (after any cost disruptor): that is what the
paper's observed-cost attack perturbs. The episode cost ``J_c`` each algorithm reacts to is the
mean observed cost of the episodes finished in the last rollout. Limits are episode costs.

* **PPO-Lagrangian** (OmniSafe's defaults: cost limit 25, multiplier init 0.001, multiplier
  learning rate 0.035 with Adam): before each update ``λ ← max(0, λ + Adam step on
  λ·(J_c - limit))``; the actor follows ``(L_r + λ·L_c) / (1 + λ)``.
* **PID-Lagrangian** (Stooke, Achiam & Abbeel, 2020; OmniSafe's CPPO-PID defaults: kp 0.1,
  ki 0.01, kd 0.01, EMAs 0.95, derivative delay 10, λ ≤ 100): λ from a PID controller on
  ``J_c - limit`` instead of gradient ascent, so it falls as soon as the cost is under the limit
  (the proportional term) instead of after the integral has unwound; the actor as PPO-Lag's.
* **CRPO** (Xu et al., 2021): the actor follows the cost surrogate alone when
  ``J_c > limit + slack``, else the reward surrogate.
* **PCRPO** (Gu et al., 2024; the paper's slack and gradient weights 0.4/0.6): cost alone
  above ``limit + slack``, reward alone below ``limit - slack``; inside the band the reward and
  cost gradients, projected onto each other's normal plane when they conflict, weighted 0.4/0.6.

Limits and slacks are *episode* costs. The paper states its limit (0.04) and slack (5e-3) on the
mean cost per step; over a 1,000-step episode its slack is 5, the default here. (A slack of
5e-3 episode-cost units is a band no estimate ever falls into: CRPO and PCRPO then make the
same updates, measured on SafetyHopper-v5.)

``L_r``/``L_c`` are PPO's clipped surrogates of the reward and the cost-reducing advantages;
the mixed objectives weight the two clipped surrogates (not one surrogate of mixed advantages).

Example:
    >>> from advgame.core.team import team_factory
    >>> fns = [team_factory("SafetyReacher-v5", preset="default")]
    >>> learner = PCRPOConfig(n_steps=64, cost_limit=5.0).make_learner(fns, 0, 128)
    >>> learner.learn(128); learner.steps
    128

"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

from advgame.agents.common.stats import EpisodeStats
from advgame.agents.marl.marl import TeamLearner, TeamPPOConfig
from advgame.agents.safe.ppo import Direction, SafeCollector, SafeModel, safe_update
from advgame.errors import ConfigError

__all__ = [
    "SAFE_LEARNERS",
    "CRPOConfig",
    "PCRPOConfig",
    "PIDLagConfig",
    "PPOLagConfig",
    "SafeLearner",
]

_SAFE_STATE = "advgame-safe-learner-v1"


def _finite(value: Any, low: float) -> bool:
    return (
        not isinstance(value, bool)
        and isinstance(value, (int, float))
        and math.isfinite(value)
        and value >= low
    )


@dataclass(frozen=True)
class SafePPOConfig(TeamPPOConfig):
    """What every constrained learner has: PPO's table, a cost critic, and a cost limit."""

    centralised: ClassVar[bool] = False
    cost_limit: float = 25.0
    """Largest allowed expected episode cost (OmniSafe's default, 25)."""
    cost_gamma: float = 0.99
    """Discount of the cost critic."""
    normalize_advantage: bool = True
    """Standardize reward and cost advantages per minibatch (OmniSafe's default)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, low in self._nonnegative():
            value = getattr(self, name)
            if not _finite(value, low):
                raise ConfigError(
                    f"{type(self).__name__}.{name} must be a finite number >= {low}, got {value!r}."
                )
        if not 0 <= self.cost_gamma <= 1:
            raise ConfigError(f"cost_gamma must be in [0, 1], got {self.cost_gamma!r}.")

    def _nonnegative(self) -> tuple[tuple[str, float], ...]:
        return (("cost_limit", 0.0),)

    def direction(self, episode_cost: float, state: dict[str, Any]) -> Direction:
        """How to combine the objectives given the estimated episode cost (subclasses)."""
        raise NotImplementedError

    def initial_state(self) -> dict[str, Any]:
        """The algorithm's own state before the first update (λ and its controller; none)."""
        return {}

    def save_state(self, state: dict[str, Any]) -> dict[str, Any]:
        """What a checkpoint keeps of `state` (entries of the constraint file; none)."""
        return {}

    def load_state(self, state: dict[str, Any], saved: Mapping[str, Any]) -> None:
        """Restore `state` in place from a constraint file's entries (`save_state`'s)."""

    def learner_class(self) -> type[SafeLearner]:
        """The constrained learner (a `TeamLearner` with a cost critic)."""
        return SafeLearner


@dataclass(frozen=True)
class PPOLagConfig(SafePPOConfig):
    """PPO-Lagrangian with OmniSafe's defaults."""

    algo: ClassVar[str] = "ppo-lag"
    multiplier_init: float = 0.001
    """Initial Lagrange multiplier λ."""
    multiplier_lr: float = 0.035
    """Adam step size of λ."""

    def _nonnegative(self) -> tuple[tuple[str, float], ...]:
        return (("cost_limit", 0.0), ("multiplier_init", 0.0), ("multiplier_lr", 0.0))

    def initial_state(self) -> dict[str, Any]:
        """λ (a tensor) and its Adam optimizer."""
        lam = torch.tensor(float(self.multiplier_init), requires_grad=True)
        return {
            "multiplier": lam,
            "multiplier_optimizer": torch.optim.Adam([lam], lr=self.multiplier_lr),
        }

    def save_state(self, state: dict[str, Any]) -> dict[str, Any]:
        """λ and its optimizer's state."""
        return {
            "multiplier": state["multiplier"].detach().clone(),
            "multiplier_optimizer": state["multiplier_optimizer"].state_dict(),
        }

    def load_state(self, state: dict[str, Any], saved: Mapping[str, Any]) -> None:
        """λ copied into its tensor, the optimizer's state loaded."""
        with torch.no_grad():
            state["multiplier"].copy_(saved["multiplier"])
        state["multiplier_optimizer"].load_state_dict(saved["multiplier_optimizer"])

    def direction(self, episode_cost: float, state: dict[str, Any]) -> Direction:
        """Step λ on ``J_c - limit`` (Adam, clamped at 0); weights 1/(1+λ), λ/(1+λ)."""
        lam, opt = state["multiplier"], state["multiplier_optimizer"]
        opt.zero_grad()
        (-lam * (episode_cost - self.cost_limit)).backward()
        opt.step()
        with torch.no_grad():
            lam.clamp_(min=0.0)
        return _lagrangian(float(lam.detach()))


@dataclass(frozen=True)
class PIDLagConfig(SafePPOConfig):
    """PID-Lagrangian (CPPO-PID) with OmniSafe's defaults."""

    algo: ClassVar[str] = "ppo-pid"
    kp: float = 0.1
    """Proportional gain, on the EMA of ``J_c - limit``."""
    ki: float = 0.01
    """Integral gain (the integral starts at `multiplier_init` and stays >= 0)."""
    kd: float = 0.01
    """Derivative gain, on the rise of the cost EMA over `d_delay` updates."""
    d_delay: int = 10
    """Updates back that the derivative compares with."""
    p_ema: float = 0.95
    """EMA factor of the proportional error."""
    d_ema: float = 0.95
    """EMA factor of the cost the derivative reads."""
    multiplier_init: float = 0.001
    """Initial integral (and λ)."""
    multiplier_max: float = 100.0
    """Largest λ."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if type(self.d_delay) is not int or self.d_delay < 1:
            raise ConfigError(f"PIDLagConfig.d_delay must be an int >= 1, got {self.d_delay!r}.")
        for name in ("p_ema", "d_ema"):
            if not 0 <= getattr(self, name) < 1:
                raise ConfigError(
                    f"PIDLagConfig.{name} must be in [0, 1), got {getattr(self, name)!r}."
                )

    def _nonnegative(self) -> tuple[tuple[str, float], ...]:
        return (("cost_limit", 0.0), ("kp", 0.0), ("ki", 0.0), ("kd", 0.0),
                ("multiplier_init", 0.0), ("multiplier_max", 0.0))  # fmt: skip

    def initial_state(self) -> dict[str, Any]:
        """The integral, the two EMAs, the cost EMAs of the last `d_delay` updates, and λ."""
        return {"integral": float(self.multiplier_init), "p": 0.0, "cost": 0.0,
                "history": [0.0], "multiplier": float(self.multiplier_init)}  # fmt: skip

    def direction(self, episode_cost: float, state: dict[str, Any]) -> Direction:
        """λ = clip(kp·EMA(δ) + Σ ki·δ (>= 0) + kd·max(0, rise of EMA(J_c)), 0, max); δ = J_c - limit."""
        delta = episode_cost - self.cost_limit
        state["integral"] = max(0.0, state["integral"] + self.ki * delta)
        state["p"] = self.p_ema * state["p"] + (1 - self.p_ema) * delta
        state["cost"] = self.d_ema * state["cost"] + (1 - self.d_ema) * episode_cost
        rise = max(0.0, state["cost"] - state["history"][0])
        raw = self.kp * state["p"] + state["integral"] + self.kd * rise
        lam = min(max(0.0, raw), self.multiplier_max)
        state["history"] = [*state["history"], state["cost"]][-self.d_delay :]
        state["multiplier"] = lam
        return _lagrangian(lam)

    def save_state(self, state: dict[str, Any]) -> dict[str, Any]:
        """The controller's numbers, as they are."""
        return {"controller": dict(state)}

    def load_state(self, state: dict[str, Any], saved: Mapping[str, Any]) -> None:
        """The controller's numbers, replaced."""
        state.clear()
        state.update(saved["controller"])


def _lagrangian(lam: float) -> Direction:
    """The Lagrangian's weights for multiplier λ: reward 1/(1+λ), cost λ/(1+λ)."""
    return Direction(1.0 / (1.0 + lam), lam / (1.0 + lam))


@dataclass(frozen=True)
class CRPOConfig(SafePPOConfig):
    """CRPO: switch to the cost objective while the episode cost exceeds limit + slack."""

    algo: ClassVar[str] = "crpo"
    slack: float = 5.0
    """Tolerance above the limit before the cost objective takes over (episode cost; the
    paper's 5e-3 per step over 1,000 steps)."""

    def _nonnegative(self) -> tuple[tuple[str, float], ...]:
        return (("cost_limit", 0.0), ("slack", 0.0))

    def direction(self, episode_cost: float, state: dict[str, Any]) -> Direction:
        """Cost alone above the limit plus slack, else reward alone."""
        unsafe = episode_cost > self.cost_limit + self.slack
        return Direction(0.0, 1.0) if unsafe else Direction(1.0, 0.0)


@dataclass(frozen=True)
class PCRPOConfig(SafePPOConfig):
    """PCRPO: soft switching with projected reward and cost gradients inside the slack band."""

    algo: ClassVar[str] = "pcrpo"
    slack: float = 5.0
    """Half-width of the band around the limit where both objectives are followed (episode
    cost; the paper's 5e-3 per step over 1,000 steps)."""
    reward_weight: float = 0.4
    """Weight of the (projected) reward gradient in the band (paper: gradient wr 0.4)."""
    cost_weight: float = 0.6
    """Weight of the (projected) cost gradient in the band (paper: gradient wc 0.6)."""

    def _nonnegative(self) -> tuple[tuple[str, float], ...]:
        return (("cost_limit", 0.0), ("slack", 0.0), ("reward_weight", 0.0), ("cost_weight", 0.0))

    def direction(self, episode_cost: float, state: dict[str, Any]) -> Direction:
        """Cost alone above the band, reward alone below it, projected gradients inside."""
        if episode_cost > self.cost_limit + self.slack:
            return Direction(0.0, 1.0)
        if episode_cost < self.cost_limit - self.slack:
            return Direction(1.0, 0.0)
        return Direction(self.reward_weight, self.cost_weight, project=True)


SAFE_LEARNERS: dict[str, type[SafePPOConfig]] = {
    "ppo-lag": PPOLagConfig,
    "ppo-pid": PIDLagConfig,
    "crpo": CRPOConfig,
    "pcrpo": PCRPOConfig,
}
"""Constrained learner configs by algorithm name."""


class SafeLearner(TeamLearner):
    """A constrained learner (by `config`) for the protagonists of the views `env_fns` build.

    It is a `TeamLearner` (the same Side protocol, actors file and checkpoints) with a cost
    critic, the observed episode cost ``J_c``, and the algorithm's state (PPO-Lagrangian's λ).
    """

    def __init__(
        self,
        config: SafePPOConfig,
        env_fns: Sequence[Callable[[], Any]],
        seed: int,
        total_steps: int,
        tensorboard_log: str | None = None,
    ) -> None:
        if not isinstance(config, SafePPOConfig) or not config.algo:
            raise ConfigError(f"SafeLearner needs a PPOLag/CRPO/PCRPO config, got {config!r}.")
        super().__init__(config, env_fns, seed, total_steps, tensorboard_log)
        c = self.collector
        self.collector: SafeCollector = SafeCollector(c.envs, config, self.rng)
        gen = torch.Generator().manual_seed(int(seed) + 1)
        self.model: SafeModel = SafeModel(
            c.obs_dims, c.act_dims, config.net_arch, config.log_std_init, gen
        )
        self.optimizer = torch.optim.Adam(
            self.model.parameters(), lr=config.learning_rate, eps=1e-5, fused=True
        )
        self.episode_cost = 0.0
        """The last estimate of the observed episode cost J_c."""
        self.algo_state: dict[str, Any] = config.initial_state()

    @property
    def multiplier(self) -> float | None:
        """The Lagrangian learners' current λ (None for CRPO and PCRPO)."""
        lam = self.algo_state.get("multiplier")
        if isinstance(lam, torch.Tensor):
            return float(lam.detach())
        return None if lam is None else float(lam)

    def learn(self, steps: int, stats: EpisodeStats | None = None) -> None:
        """Train for (at least) `steps` more environment steps."""
        cfg = self.config
        assert isinstance(cfg, SafePPOConfig)
        self.collector.training = True
        target = self.steps + steps
        while self.steps < target:
            lr = cfg.learning_rate * (
                max(1.0 - self.steps / self.total_steps, 0.0) if cfg.lr_decay else 1.0
            )
            data = self.collector.collect(self.model, self.generator, stats)
            self.steps += cfg.n_steps * len(self.envs)
            finished = self.collector.finished_costs  # this rollout's episodes
            if finished:
                self.episode_cost = float(np.mean(finished))
            way = cfg.direction(self.episode_cost, self.algo_state)
            for group in self.optimizer.param_groups:
                group["lr"] = lr
            diagnostics = safe_update(self.model, self.optimizer, data, cfg, self.generator, way)
            self._record(
                {
                    **diagnostics,
                    "learning_rate": lr,
                    "episode_cost": self.episode_cost,
                    "reward_weight": way.reward_weight,
                    "cost_weight": way.cost_weight,
                }
            )

    def save(self, folder: Path, deterministic: bool = True) -> Any:
        """Actors and the learner state (as `TeamLearner.save`), plus the constraint state."""
        specs = super().save(folder, deterministic)
        extra: dict[str, Any] = {"format": _SAFE_STATE, "episode_cost": self.episode_cost}
        extra.update(self.config.save_state(self.algo_state))
        torch.save(extra, Path(folder) / f"{self.config.algo}_constraint.pt")
        return specs

    @classmethod
    def load(
        cls,
        folder: Path,
        config: SafePPOConfig,
        env_fns: Sequence[Callable[[], Any]],
        tensorboard_log: str | None = None,
    ) -> SafeLearner:
        """Rebuild a learner saved by `save`: weights, normalizers, generators, λ and J_c."""
        learner = super().load(folder, config, env_fns, tensorboard_log)
        assert isinstance(learner, SafeLearner)
        path = Path(folder) / f"{config.algo}_constraint.pt"
        if not path.exists():
            raise ConfigError(f"No {config.algo} constraint state at {path}.")
        extra = torch.load(path, map_location="cpu", weights_only=True)
        learner.episode_cost = float(extra["episode_cost"])
        config.load_state(learner.algo_state, extra)
        return learner
