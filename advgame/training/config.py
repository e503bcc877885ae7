"""What a training run is: `TrainConfig`, the named `METHODS`, and the learner configs.

The first link of the training chain, which points one way::

    train_config (TrainConfig, METHODS, learner_config)
      -> trainer (Trainer: update_protagonists, update_adversaries, snapshot)
      -> loop (Run: persistence, resume, progress.csv, TensorBoard, logging)
      -> training (train, resume)
"""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass
from typing import Any, Literal

from advgame.core.fields import check_fields
from advgame.core.registry import load
from advgame.errors import ConfigError
from advgame.training.conditions import check_conditions

__all__ = [
    "METHODS",
    "OMPO_CORR10",
    "PROTAGONISTS",
    "SAFE_ALGOS",
    "TEAM_ALGOS",
    "TrainConfig",
    "learner_config",
]

_LEARNERS = "advgame.agents.learners:LEARNERS"
_TEAM_LEARNERS = "advgame.agents.marl.marl:MARL_LEARNERS"
_SAFE_LEARNERS = "advgame.agents.safe.safe:SAFE_LEARNERS"
SAFE_ALGOS = ("ppo-lag", "ppo-pid", "crpo", "pcrpo")
"""Constrained protagonist learners (safe scenarios): PPO-Lagrangian, PID-Lagrangian, CRPO,
PCRPO."""
TEAM_ALGOS = ("mappo", "ippo", *SAFE_ALGOS)
"""Protagonist learners that train the whole protagonist team on team views
(`advgame.core.team.TeamView`; our torch learners) instead of one SB3 agent."""
PROTAGONISTS = "protagonists"
"""The key of the protagonist side in `Trainer.sides` (one agent or a whole team)."""

OMPO_CORR10 = 0.75
"""OMPO's reward-correction weight that makes the correction about 10 % of the reward: on the
released ``hopper-ompo/ompo`` agent's own transitions (8 episodes of its training schedule,
4,365 steps) the discriminator's mean ``|logit|`` is 0.61 and the shifted reward 4.65, so OMPO's
1e-3 is 0.013 % of it and 0.75 is 10 % (docs/ompo.md, "Does the discriminator matter?")."""


def _raw(algo: str, hparams: dict[str, Any]) -> dict[str, Any]:
    """A method training `algo` with `hparams` on raw observations and rewards, nominal preset."""
    return {
        "preset": "default",
        "learned": [],
        "train_budget_scale": 1.0,
        "protagonist_algo": algo,
        "normalize": False,
        "protagonist_hparams": hparams,
    }


METHODS: dict[str, dict[str, Any]] = {
    "ppo": {"preset": "default", "learned": [], "train_budget_scale": 1.0},
    "atla": {"preset": "atla", "learned": None, "train_budget_scale": 1.0},
    "rarl": {"preset": "rarl", "learned": None, "train_budget_scale": 0.5},
    "sa-ppo": {
        "preset": "default",
        "learned": [],
        "train_budget_scale": 1.0,
        "protagonist_algo": "sa-ppo",
    },
    "pgd-at": {
        "preset": "atla",
        "learned": [],
        "train_budget_scale": 1.0,
        "adversaries": {"observation_adversary": "mad"},
    },
    "atla-sa": {
        "preset": "atla",
        "learned": None,
        "train_budget_scale": 1.0,
        "protagonist_algo": "sa-ppo",
    },
    "atla-lstm": {
        "preset": "atla",
        "learned": None,
        "train_budget_scale": 1.0,
        "protagonist_algo": "recurrent-ppo",
        "adversary_algo": "recurrent-ppo",
    },
    "atla-lstm-sa": {
        "preset": "atla",
        "learned": None,
        "train_budget_scale": 1.0,
        "protagonist_algo": "sa-recurrent-ppo",
        "adversary_algo": "recurrent-ppo",
    },
    "sac": {
        "preset": "default",
        "learned": [],
        "train_budget_scale": 1.0,
        "protagonist_algo": "sac",
        "normalize": False,
    },
    "ompo": {
        "preset": "default",
        "learned": [],
        "train_budget_scale": 1.0,
        "protagonist_algo": "ompo",
        "normalize": False,
    },
    "dbc": {
        "preset": "default",
        "learned": [],
        "train_budget_scale": 1.0,
        "protagonist_algo": "dbc",
        "normalize": False,
    },
    "rsc": {
        "preset": "default",
        "learned": [],
        "train_budget_scale": 1.0,
        "protagonist_algo": "rsc",
        "normalize": False,
    },
    "sac-rsc-matched": _raw(
        "sac",
        {
            "learning_rate": 3e-4,
            "critic_learning_rate": 1e-3,
            "net_arch": [256, 256, 256],
            "learning_starts": 0,
            "batch_size": 128,
            "ent_coef": "auto_0.1",
            "n_steps": 4,
        },
    ),
    "sac-dbc-matched": _raw(
        "sac",
        {
            "learning_rate": 3e-4,
            "critic_learning_rate": 1e-3,
            "net_arch": [256, 256, 256],
            "learning_starts": 1000,
            "batch_size": 128,
            "ent_coef": "auto_0.1",
            "actor_update_interval": 2,
        },
    ),
    "sac-ompo-matched": _raw(
        "sac",
        {
            "learning_rate": 3e-4,
            "net_arch": [256, 256],
            "networks": "ompo",
            "learning_starts": 5000,
            "batch_size": 256,
            "ent_coef": "auto_0.2",
            "gradient_steps": 3,
            "actor_update_interval": 2,
        },
    ),
    "rsc-noaug": _raw("rsc", {"augmented_ratio": 0.0}),
    "ompo-nocorr": _raw("ompo", {"correction_weight": 0.0}),
    "ompo-corr10": _raw("ompo", {"correction_weight": OMPO_CORR10}),
    **{
        algo: {
            "preset": "default",
            "learned": [],
            "train_budget_scale": 1.0,
            "protagonist_algo": algo,
        }
        for algo in SAFE_ALGOS
    },
}
"""Named starting points: plain PPO on the nominal task, ATLA (learned observation attack in
normalized units), RARL (learned forces, trained at half the bound, tested at full), SA-PPO
(nominal training with the state-adversarial regulariser, `advgame.agents.SAPPOConfig`),
ATLA-SA (ATLA's alternation with an SA-PPO protagonist), ATLA-LSTM (ATLA's alternation with an
LSTM protagonist, `advgame.agents.RecurrentPPOConfig`), ATLA-LSTM-SA (the same with
SA-PPO's regulariser on the LSTM protagonist, `advgame.agents.sa.recurrent`; both pair it with
an LSTM adversary, as ATLA does), PGD-AT (adversarial training on the
current policy: a MAD attack on the learner itself during every rollout), SAC and OMPO on raw observations and rewards, as OMPO's authors train (occupancy
matching under shifting dynamics, `advgame.agents.ompo.ompo`; ``--preset ompo-nonstationary`` gives
its shifting tasks), DBC on raw observations and rewards as its authors train (a bisimulation
encoder on SB3's SAC, `advgame.agents.dbc.dbc`), RSC likewise (SAC on real transitions mixed with
augmented ones from a causal world model, `advgame.agents.rsc.rsc`), and the constrained learners on a
safe scenario (``--preset`` picks the in-training disruption).

Controls, so that a comparison isolates its method (docs/causal.md, docs/ompo.md): SAC with
the networks, batch, n-step returns, step sizes, temperature handling, start steps and update
schedule of the method it stands beside (``sac-rsc-matched``, ``sac-dbc-matched``,
``sac-ompo-matched``: `advgame.agents.SACConfig`'s matching fields; a test checks each against
the method's config), RSC without its augmented rows (``rsc-noaug``: augmented ratio 0, the
world model still trains) and OMPO without its reward correction (``ompo-nocorr``) or with
one of about 10 % of the reward (``ompo-corr10``, `OMPO_CORR10`)."""


@dataclass(frozen=True)
class TrainConfig:
    """Everything a training run needs; saved as ``config.json`` in the run directory."""

    scenario: str = "Hopper-v5"
    """Registered scenario id."""
    preset: str = "atla"
    """Scenario preset giving the disruptors (and any fixed adversary policies)."""
    learned: list[str] | None = None
    """Adversary agents trained in the adversary phase (None: every adversary the preset gives
    no fixed policy; []: none, i.e. plain training against fixed or no-op adversaries)."""
    protagonist_algo: Literal[
        "ppo",
        "sa-ppo",
        "sac",
        "td3",
        "ompo",
        "dbc",
        "rsc",
        "recurrent-ppo",
        "sa-recurrent-ppo",
        "mappo",
        "ippo",
        "ppo-lag",
        "ppo-pid",
        "crpo",
        "pcrpo",
    ] = "ppo"
    """Protagonist learner: SB3 PPO/SAC/TD3, OMPO (SAC with OMPO's losses), DBC (SAC on a bisimulation encoder), RSC (SAC on causally augmented data), RecurrentPPO (sb3-contrib's LSTM PPO), or SA-PPO (PPO with the state-adversarial
    regulariser) for one protagonist, MAPPO/IPPO for a team, or a constrained learner
    (PPO-Lagrangian, PID-Lagrangian, CRPO, PCRPO) on a safe scenario."""
    adversary_algo: Literal["ppo", "sac", "recurrent-ppo"] = "ppo"
    """Learner of each learned adversary (``"recurrent-ppo"``: an LSTM adversary)."""
    protagonist_hparams: dict[str, Any] | None = None
    """Overrides of the protagonist learner config (e.g. {"n_steps": 512})."""
    adversary_hparams: dict[str, Any] | None = None
    """Overrides of the adversary learner config."""
    iterations: int = 10
    """Alternation iterations."""
    protagonist_steps: int = 2048
    """Protagonist steps per iteration (ATLA: one PPO update of 2048 steps)."""
    adversary_steps: int = 2048
    """Steps per learned adversary per iteration."""
    warmup_steps: int = 0
    """Protagonist steps against no-op adversaries before the first iteration."""
    sampling: Literal["latest", "uniform", "fictitious"] = "latest"
    """How protagonist-phase opponents are drawn from the population: the latest snapshot,
    uniform over all members (the no-op included), or fictitious play (past snapshots)."""
    snapshot_every: int = 1
    """Add the adversaries to the population every this many iterations."""
    train_budget_scale: float = 1.0
    """Scale of every budget while training (RARL trains at a fraction, tests at full)."""
    normalize: bool = True
    """Normalize observations and rewards (VecNormalize) for every learner."""
    n_envs: int = 1
    """Views per learner."""
    vec_env: Literal["dummy", "subproc"] = "dummy"
    """VecEnv kind; "dummy" is faster for cheap MuJoCo tasks on 2 cores."""
    eval_episodes: int = 2
    """Episodes of the quick evaluation logged at every iteration (per condition, with
    `eval_conditions`)."""
    eval_conditions: list[str] | None = None
    """The paper's in-training protocol: named test conditions (``"preset:NAME"``,
    ``"training"``: `advgame.training.conditions`) in which the deterministic protagonist plays
    `eval_episodes` episodes after every iteration, logged as ``eval_<name>_return`` in
    ``progress.csv`` in place of the nominal and attacked returns (None: those two)."""
    seed: int = 0
    """Seeds models, environments and population sampling."""
    disruptors: dict[str, Any] | None = None
    """The run's disruptors as `advgame.make` takes them (``{kind: options}``, e.g.
    ``{"observation": {"eps": 0.05}}``), instead of `preset`'s."""
    task_options: dict[str, Any] | None = None
    """Options of the task base, as `advgame.make`'s keywords (``max_episode_steps``, a safe
    task's ``threshold``)."""
    adversaries: dict[str, Any] | None = None
    """Fixed (not learned) adversary policies by agent id, over the preset's own: text or dict
    specs (`advgame.adversaries.specs`: ``"gauss:0.1"``, ``"random"``, ``"llm"``,
    ``{"kind": "uniform", "low": -0.2, "high": 0.2}``). They play in both phases and are never
    trained."""

    def game_options(self) -> dict[str, Any]:
        """`advgame.make`'s keywords for this run's game (``disruptors`` or ``preset``, task options)."""
        base = (
            {"disruptors": self.disruptors}
            if self.disruptors is not None
            else {"preset": self.preset}
        )
        return {**base, **(self.task_options or {})}

    def fixed_adversaries(self) -> dict[str, Any]:
        """The specs of `adversaries`, parsed (`advgame.adversaries.specs.adversary_spec`)."""
        parse = load("advgame.adversaries.specs:adversary_spec")
        return {agent: parse(spec) for agent, spec in (self.adversaries or {}).items()}

    def __post_init__(self) -> None:
        check_fields(self)
        for name in ("iterations", "protagonist_steps", "n_envs", "snapshot_every"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ConfigError(
                    f"TrainConfig.{name} must be an int >= 1, got {getattr(self, name)!r}."
                )
        for name in ("adversary_steps", "warmup_steps", "eval_episodes"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 0:
                raise ConfigError(
                    f"TrainConfig.{name} must be an int >= 0, got {getattr(self, name)!r}."
                )
        for name in ("protagonist_algo", "adversary_algo", "sampling", "vec_env"):
            allowed = typing.get_args(typing.get_type_hints(TrainConfig)[name])
            if getattr(self, name) not in allowed:
                raise ConfigError(
                    f"TrainConfig.{name} must be one of {allowed}, got {getattr(self, name)!r}."
                )
        if self.learned is not None and (
            not isinstance(self.learned, (list, tuple))
            or not all(isinstance(a, str) for a in self.learned)
        ):
            raise ConfigError(
                f"TrainConfig.learned must be None or a list of adversary ids, got {self.learned!r}"
                ' (e.g. ["observation_adversary"]).'
            )
        scale = self.train_budget_scale
        if (
            isinstance(scale, bool)
            or not isinstance(scale, (int, float))
            or not 0 < scale < math.inf
        ):
            raise ConfigError(f"train_budget_scale must be a number > 0, got {scale!r}.")
        for name in ("protagonist_hparams", "adversary_hparams", "disruptors", "task_options",
                     "adversaries"):  # fmt: skip
            if getattr(self, name) is not None and not isinstance(getattr(self, name), dict):
                raise ConfigError(
                    f"TrainConfig.{name} must be a dict, got {getattr(self, name)!r}."
                )
        self.fixed_adversaries()  # a malformed adversary spec fails here, before any run
        check_conditions(self.eval_conditions, self.eval_episodes)


def learner_config(algo: str, overrides: dict[str, Any] | None) -> Any:
    """The learner config of `algo` with `overrides` applied (unknown names are an error)."""
    from advgame.core.config import from_dict, to_dict

    learners = {**load(_LEARNERS)}
    if algo in TEAM_ALGOS:
        learners.update(load(_SAFE_LEARNERS if algo in SAFE_ALGOS else _TEAM_LEARNERS))
    if algo not in learners:
        raise ConfigError(f"Unknown learner {algo!r}; expected one of {sorted(learners)}.")
    base = learners[algo]()
    return from_dict(type(base), {**to_dict(base), **(overrides or {})})
