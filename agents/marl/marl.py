"""MAPPO and IPPO for the protagonist team of a game, compact torch learners on team views.

Only MAPPO/IPPO over MaMuJoCo have no maintained library behind them here, so they are written
out (design invariant 6). Both train one Gaussian actor per protagonist on its own (perturbed)
observation; they differ in the critic:

* **MAPPO** (Yu et al., 2022): a centralised critic on the true global state `TeamView.state`.
* **IPPO** (de Witt et al., 2020): one critic per protagonist on its local observation.

`TeamLearner` follows the protocol of `advgame.agents.common.side.Side` (``agents``, ``steps``, ``learn``,
``freeze``, ``set_policies``, ``set_observation_scale``, ``observation_std``, ``save``,
``load``, ``close``), so the alternation loop drives it like any other side. Its views are
stepped in sync in this process. Every random draw of a run comes from the two generators made
in `TeamLearner._seed`: a seeded run reproduces exactly (with ``torch.set_num_threads(1)``).

When the protagonists are homogeneous and may share one policy, IPPO with parameter sharing runs
on Stable-Baselines3 through SuperSuit instead: `advgame.agents.marl.shared.SharedIPPO`.

Example:
    >>> from advgame.core.team import team_factory
    >>> fns = [team_factory("MA-HalfCheetah-2x3", preset="default")]
    >>> learner = TeamLearner(MAPPOConfig(n_steps=64), fns, seed=0, total_steps=128)
    >>> learner.learn(128); learner.steps
    128

"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

from advgame.agents.common.stats import EpisodeStats
from advgame.agents.marl.collect import TeamCollector
from advgame.agents.marl.nets import (
    ACTORS_FORMAT,
    NumpyMLP,
    TeamModel,
    TorchActorCheckpoint,
    actor_record,
)
from advgame.agents.marl.ppo import ppo_update
from advgame.errors import ConfigError

__all__ = ["MARL_LEARNERS", "IPPOConfig", "MAPPOConfig", "TeamLearner", "TeamPPOConfig"]

log = logging.getLogger(__name__)

_STATE_FORMAT = "advgame-team-learner-v1"


def _positive_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


_CHECKS: tuple[tuple[tuple[str, ...], Callable[[Any], Any], str], ...] = (
    (("learning_rate", "clip_range", "max_grad_norm", "clip_obs"), lambda v: v > 0, "> 0"),
    (("n_steps", "n_epochs", "batch_size"), _positive_int, "an int > 0"),
    (("gamma", "gae_lambda"), lambda v: 0 <= v <= 1, "in [0, 1]"),
    (("vf_coef", "ent_coef"), lambda v: v >= 0, ">= 0"),
    (("log_std_init",), math.isfinite, "finite"),
    (
        ("target_kl",),
        lambda v: v is None or (not isinstance(v, bool) and math.isfinite(v) and v > 0),
        "a number > 0 or None",
    ),
)
"""Config validation: (fields, predicate, what is expected)."""


@dataclass(frozen=True)
class TeamPPOConfig:
    """PPO for a protagonist team, with the paper's PPO/MAPPO/IPPO table as defaults."""

    algo: ClassVar[str] = ""
    centralised: ClassVar[bool] = False
    learning_rate: float = 3e-4
    """Adam step size."""
    lr_decay: bool = True
    """Decay the learning rate linearly to 0 over the run's `total_steps` (paper: True)."""
    gamma: float = 0.99
    """Discount factor."""
    gae_lambda: float = 0.95
    """GAE λ."""
    clip_range: float = 0.2
    """PPO ratio clip ε."""
    net_arch: tuple[int, ...] = (64, 64)
    """Hidden layer sizes of every actor and critic."""
    n_steps: int = 2048
    """Steps per environment per rollout (paper: 2048 steps per collect)."""
    n_epochs: int = 10
    """Optimisation epochs per rollout (paper: repeat per collect 10)."""
    batch_size: int = 64
    """Minibatch size (samples; each holds every agent's transition)."""
    vf_coef: float = 0.25
    """Value loss coefficient."""
    ent_coef: float = 0.0
    """Entropy bonus coefficient."""
    max_grad_norm: float = 0.5
    """Gradient norm clip, per network."""
    normalize_observations: bool = True
    """Running mean/std normalization of each agent's observation (and of the global state)."""
    normalize_reward: bool = True
    """Scale each agent's reward by the std of its discounted return (paper: rew norm True)."""
    normalize_advantage: bool = False
    """Standardize advantages per minibatch (paper: norm adv 0)."""
    clip_obs: float = 10.0
    """Normalized observations (and scaled rewards) are clipped to ±this."""
    log_std_init: float = 0.0
    """Initial log standard deviation of every actor's Gaussian."""
    target_kl: float | None = None
    """Stop a rollout's epochs early once the policy's mean KL from the rollout's policy (over
    the whole rollout, any agent) exceeds this (OmniSafe: 0.02 with 40 epochs); None: never."""

    def __post_init__(self) -> None:
        for names, ok, expected in _CHECKS:
            for name in names:
                value = getattr(self, name)
                try:
                    good = bool(ok(value))
                except TypeError:  # e.g. a string where a number belongs
                    good = False
                if not good:
                    raise ConfigError(
                        f"{type(self).__name__}.{name} must be {expected}, got {value!r}."
                    )
        if not self.net_arch or not all(_positive_int(h) for h in self.net_arch):
            raise ConfigError(
                f"{type(self).__name__}.net_arch must be a non-empty tuple of positive ints, "
                f"got {self.net_arch!r}."
            )

    def make_learner(
        self,
        env_fns: Sequence[Callable[[], Any]],
        seed: int,
        total_steps: int,
        tensorboard_log: str | None = None,
    ) -> TeamLearner:
        """A `TeamLearner` with this config on the team views `env_fns` build."""
        return self.learner_class()(self, env_fns, seed, total_steps, tensorboard_log)

    def load_learner(
        self,
        folder: Path,
        env_fns: Sequence[Callable[[], Any]],
        tensorboard_log: str | None = None,
    ) -> TeamLearner:
        """The learner with this config saved in `folder` (to resume a run)."""
        return self.learner_class().load(folder, self, env_fns, tensorboard_log)

    def learner_class(self) -> type[TeamLearner]:
        """The learner this config builds (constrained configs build a subclass)."""
        return TeamLearner


@dataclass(frozen=True)
class MAPPOConfig(TeamPPOConfig):
    """MAPPO: per-agent actors, a centralised critic on the global state (paper's table)."""

    algo: ClassVar[str] = "mappo"
    centralised: ClassVar[bool] = True


@dataclass(frozen=True)
class IPPOConfig(TeamPPOConfig):
    """IPPO: an actor and a critic per agent, each on the agent's observation (paper's table)."""

    algo: ClassVar[str] = "ippo"
    centralised: ClassVar[bool] = False


MARL_LEARNERS: dict[str, type[TeamPPOConfig]] = {"mappo": MAPPOConfig, "ippo": IPPOConfig}
"""Multi-agent learner configs by algorithm name."""


class TeamLearner:
    """MAPPO or IPPO (by `config`) for every protagonist of the team views `env_fns` build.

    Args:
        config: a `MAPPOConfig` or `IPPOConfig`.
        env_fns: thunks building `advgame.core.team.TeamView`s (`advgame.core.team.team_factory`); all
            are stepped in sync in this process, one rollout holds ``n_steps`` of each.
        seed: seeds the weights, the action noise, the minibatch order and the episode seeds.
        total_steps: planned environment steps of the whole run (for the learning-rate decay).
        tensorboard_log: a folder for TensorBoard scalars (under ``<folder>/<algo>``), or None.

    """

    def __init__(
        self,
        config: TeamPPOConfig,
        env_fns: Sequence[Callable[[], Any]],
        seed: int,
        total_steps: int,
        tensorboard_log: str | None = None,
    ) -> None:
        if not isinstance(config, TeamPPOConfig) or not config.algo:
            raise ConfigError(f"TeamLearner needs a MAPPOConfig or IPPOConfig, got {config!r}.")
        if not env_fns:
            raise ConfigError(
                "TeamLearner needs at least one view thunk (advgame.core.team.team_factory)."
            )
        if not isinstance(total_steps, int) or total_steps < 1:
            raise ConfigError(f"total_steps must be an int >= 1, got {total_steps!r}.")
        self.config = config
        self.total_steps = total_steps
        self.steps = 0
        """Environment steps trained on (each synchronous step of n views counts n)."""
        self.tensorboard_log = tensorboard_log
        self.diagnostics: dict[str, float] = {}
        """The last update's scalars (losses, entropy, epochs run, learning rate, ...)."""
        self._writer: Any = None
        self._seed(seed)
        self.collector = TeamCollector([fn() for fn in env_fns], config, self.rng)
        self.agents: list[str] = list(self.collector.agents)
        c = self.collector
        self.model = TeamModel(
            c.obs_dims,
            c.act_dims,
            c.state_dim,
            config.net_arch,
            config.log_std_init,
            self.generator,
        )
        self.optimizer = torch.optim.Adam(
            self.model.parameters(), lr=config.learning_rate, eps=1e-5, foreach=True
        )

    def _seed(self, seed: int) -> None:
        """The one place a run's randomness comes from (no global generator is touched)."""
        self.rng = np.random.default_rng(seed)
        """Draws the seed of every episode of every view."""
        self.generator = torch.Generator().manual_seed(int(seed))
        """Draws the initial weights, the action noise and the minibatch order."""

    @property
    def envs(self) -> list[Any]:
        """The team views."""
        return self.collector.envs

    # -- the Side protocol --------------------------------------------------------------------
    def learn(self, steps: int, stats: EpisodeStats | None = None) -> None:
        """Train for (at least) `steps` more environment steps, normalizers updating.

        Each finished episode's true team return goes to ``stats.true_returns``; every
        environment step advances ``stats.progress``.
        """
        cfg = self.config
        self.collector.training = True
        target = self.steps + steps
        while self.steps < target:
            lr = cfg.learning_rate * (
                max(1.0 - self.steps / self.total_steps, 0.0) if cfg.lr_decay else 1.0
            )
            data = self.collector.collect(self.model, self.generator, stats)
            self.steps += cfg.n_steps * len(self.envs)
            for group in self.optimizer.param_groups:
                group["lr"] = lr
            diagnostics = ppo_update(self.model, self.optimizer, data, cfg, self.generator)
            self._record({**diagnostics, "learning_rate": lr})

    def freeze(self) -> None:
        """Stop updating the observation, state and reward normalizers (until `learn`)."""
        self.collector.training = False

    def set_policies(self, policies: Mapping[str, Any], index: int | None = None) -> None:
        """Replace embedded adversary policies in every team view (or view `index`)."""
        for env in self.envs if index is None else [self.envs[index]]:
            env.set_policies(dict(policies))

    def set_observation_scale(self, target: str, std: np.ndarray) -> None:
        """Pass a protagonist's normalizer std to normalized-space observation disruptors."""
        for env in self.envs:
            env.set_observation_scale(target, std)

    def observation_std(self) -> dict[str, np.ndarray] | None:
        """Each protagonist's current observation-normalizer std (None if unnormalized)."""
        norms = self.collector.observation_norms()
        return {a: n.std for a, n in norms.items()} if norms else None

    def predict(self, observations: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """The deterministic (mean) action of every protagonist for raw `observations`."""
        out = {}
        for a in self.agents:
            mean = NumpyMLP(self.model.actor(a).mean)(self.collector.normalize(a, observations[a]))
            out[a] = np.clip(mean[0], *self.collector.bounds[a]).astype(np.float32)
        return out

    def save(self, folder: Path, deterministic: bool = True) -> dict[str, TorchActorCheckpoint]:
        """Write the actors (with normalizers) and the learner state; one spec per protagonist."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        algo, norms = self.config.algo, self.collector.observation_norms()
        actors = {
            a: actor_record(self.model.actors[a], norms.get(a), *self.collector.bounds[a])
            for a in self.agents
        }
        path = folder / f"{algo}_actors.pt"
        torch.save({"format": ACTORS_FORMAT, "algo": algo, "actors": actors}, path)
        torch.save(self._state_dict(), folder / f"{algo}_learner.pt")
        return {a: TorchActorCheckpoint(str(path), a, deterministic) for a in self.agents}

    @classmethod
    def load(
        cls,
        folder: Path,
        config: TeamPPOConfig,
        env_fns: Sequence[Callable[[], Any]],
        tensorboard_log: str | None = None,
    ) -> TeamLearner:
        """Rebuild a learner saved by `save` (to resume a run).

        Restores weights, optimizer, normalizers, step count and generators; the views start
        fresh episodes.
        """
        path = Path(folder) / f"{config.algo}_learner.pt"
        if not path.exists():
            raise ConfigError(f"No {config.algo} learner state at {path}.")
        state = torch.load(path, map_location="cpu", weights_only=True)
        if state.get("format") != _STATE_FORMAT or state.get("algo") != config.algo:
            raise ConfigError(f"{path} is not a {config.algo} learner state ({_STATE_FORMAT}).")
        learner = cls(config, env_fns, 0, int(state["total_steps"]), tensorboard_log)
        if learner.agents != list(state["agents"]):
            raise ConfigError(
                f"{path} was saved for agents {state['agents']}, the views have {learner.agents}."
            )
        learner.model.load_state_dict(state["model"])
        learner.optimizer.load_state_dict(state["optimizer"])
        learner.collector.load_state_dict(state["normalizers"])
        learner.steps = int(state["steps"])
        learner.rng.bit_generator.state = state["rng"]
        learner.generator.set_state(state["generator"])
        for env, where in zip(learner.envs, state.get("schedules", ()), strict=False):
            env.resume_schedules(where)  # shifting tasks go on after the saved episodes
        return learner

    def close(self) -> None:
        """Close the views (and the TensorBoard writer)."""
        self.collector.close()
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    # -- state and logging --------------------------------------------------------------------
    def _state_dict(self) -> dict[str, Any]:
        return {
            "format": _STATE_FORMAT,
            "algo": self.config.algo,
            "agents": list(self.agents),
            "model": self.model.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "normalizers": self.collector.state_dict(),
            "steps": self.steps,
            "total_steps": self.total_steps,
            "rng": self.rng.bit_generator.state,
            "generator": self.generator.get_state(),
            "schedules": [env.schedule_positions() for env in self.envs],
        }

    def _record(self, scalars: Mapping[str, float]) -> None:
        self.diagnostics = dict(scalars)
        log.debug("%s at %d steps: %s", self.config.algo, self.steps, dict(scalars))
        if self.tensorboard_log is None:
            return
        if self._writer is None:
            from torch.utils.tensorboard import SummaryWriter

            self._writer = SummaryWriter(str(Path(self.tensorboard_log) / self.config.algo))
        for key, value in scalars.items():
            self._writer.add_scalar(f"{self.config.algo}/{key}", value, self.steps)
