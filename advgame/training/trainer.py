"""The trainer: one iteration of the alternation loop as three named steps.

As in PSRO::

    update_protagonists()   # train the protagonist vs adversaries drawn from the population
    update_adversaries()    # train each learned adversary vs the frozen protagonist
    snapshot()              # save the adversaries, grow the population

`advgame.training.loop.Run` drives a `Trainer` through its iterations and persists them.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from advgame.agents.common.stats import EpisodeStats
from advgame.core.registry import make
from advgame.errors import ConfigError
from advgame.training.conditions import check_presets
from advgame.training.config import PROTAGONISTS, TEAM_ALGOS, TrainConfig
from advgame.training.population import Member, Population

__all__ = ["Trainer", "scaled"]

log = logging.getLogger(__name__)


def scaled(spec: Any, factor: float) -> Any:
    """A disruptor spec with its budget multiplied by `factor` (RARL's training fraction)."""
    if factor == 1.0:
        return spec
    changes = {}
    for name in ("eps", "max_force", "max_torque", "alpha", "scale"):
        if hasattr(spec, name):
            value = np.asarray(getattr(spec, name), dtype=float) * factor
            changes[name] = (
                min(float(value), 1.0)
                if name == "alpha"
                else (float(value) if value.ndim == 0 else tuple(value.tolist()))
            )
    return replace(spec, **changes)


class Trainer:
    """Runs (or resumes) the alternation loop of `config` in `run_dir`."""

    def __init__(
        self, config: TrainConfig, run_dir: str | Path, progress: bool | str = True
    ) -> None:
        if progress not in (True, False, "lines"):
            raise ConfigError(f"progress must be True, False or 'lines', got {progress!r}.")
        self.cfg = config
        self.dir = Path(run_dir)
        self.progress = progress
        probe = make(config.scenario, **config.game_options())
        check_presets(config.scenario, config.eval_conditions)  # hours before the first point
        self.protagonists: tuple[str, ...] = probe.protagonists
        self.team = config.protagonist_algo in TEAM_ALGOS
        if len(self.protagonists) > 1 and not self.team:
            raise ConfigError(
                f"{config.scenario} has {len(self.protagonists)} protagonists; train them with "
                f"protagonist_algo='mappo' or 'ippo', not {config.protagonist_algo!r}."
            )
        preset = probe.preset
        self.fixed = {
            **(preset.adversaries if preset is not None else {}),
            **config.fixed_adversaries(),
        }
        stray = set(self.fixed) - set(probe.adversaries)
        if stray:
            raise ConfigError(
                f"adversaries names {sorted(stray)}, not adversaries of this game "
                f"{list(probe.adversaries)}."
            )
        self.learned = (
            list(config.learned)
            if config.learned is not None
            else [a for a in probe.adversaries if a not in self.fixed]
        )
        for a in self.learned:
            if a not in probe.adversaries:
                raise ConfigError(
                    f"learned names {a!r}, not an adversary of this game {probe.adversaries}."
                )
        self.normalized_targets = probe.scaled_targets
        probe.close()
        self.train_kwargs = {
            "disruptors": [
                scaled(d.spec, config.train_budget_scale) for d in probe.disruptors.values()
            ],
            **(config.task_options or {}),
        }
        self.rng = np.random.default_rng(config.seed)
        self.population = Population()
        self.iteration = 0
        self.sides: dict[str, Any] = {}
        """`PROTAGONISTS` -> the protagonist side; each learned adversary id -> its side."""
        self.latest: dict[str, Any] = {}
        """Each learned adversary's spec as saved this iteration (in the population or not)."""

    # -- the three steps --------------------------------------------------------------------
    def update_protagonists(self, stats: EpisodeStats) -> None:
        """Train the protagonist against opponents drawn from the population."""
        side = self.sides[PROTAGONISTS]
        for i in range(self.cfg.n_envs):
            drawn = {
                a: self.population.sample(a, self.cfg.sampling, self.rng).opponent_spec()
                for a in self.learned
            }
            side.set_policies(drawn, index=i)
        self._push_scale(side, side)
        side.learn(self.cfg.protagonist_steps, stats)

    def update_adversaries(self, stats: EpisodeStats, frozen: dict[str, Any]) -> None:
        """Train each learned adversary against the frozen protagonists (and latest fellows).

        `frozen` maps every protagonist id to the spec of its just-saved policy.
        """
        prot = self.sides[PROTAGONISTS]
        prot.freeze()
        for agent in self.learned:
            side = self.sides[agent]
            fellows = {
                a: self.population.of(a)[-1].opponent_spec() for a in self.learned if a != agent
            }
            side.set_policies({**frozen, **fellows})
            self._push_scale(side, prot)
            if self.cfg.adversary_steps:
                side.learn(self.cfg.adversary_steps, stats)

    def snapshot(self, folder: Path) -> None:
        """Save the adversaries, add them to the population every `snapshot_every` iterations."""
        keep = (
            self.iteration % self.cfg.snapshot_every == 0 or self.iteration == self.cfg.iterations
        )
        for agent in self.learned:
            spec = self.sides[agent].save(folder)
            final = replace(
                spec, path=spec.path.replace(".partial", ""), normalizer=_final(spec.normalizer)
            )
            self.latest[agent] = final
            if keep:
                self.population.add(
                    Member(
                        f"{agent}@{self.iteration}",
                        "adversary",
                        agent,
                        final,
                        self.iteration,
                        meta={"scenario": self.cfg.scenario},
                    )
                )

    # -- helpers ----------------------------------------------------------------------------
    def _push_scale(self, side: Any, source: Any) -> None:
        """Give `side`'s games the normalizer std of `source` (the protagonist side)."""
        if not self.normalized_targets:
            return
        std = source.observation_std()
        stds = std if isinstance(std, dict) else {self.protagonists[0]: std}
        if std is not None:
            for target, value in stds.items():
                side.set_observation_scale(target, value)

    def protagonist_specs(self, saved: Any) -> dict[str, Any]:
        """What the protagonist side's `save` returned, as ``{protagonist id: spec}``."""
        return dict(saved) if isinstance(saved, dict) else {self.protagonists[0]: saved}


def _final(path: str | None) -> str | None:
    """The path a file in an ``iter_NNNN.partial`` folder has once the folder is committed."""
    return None if path is None else path.replace(".partial", "")
