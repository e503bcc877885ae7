"""The one zero-sum training loop: ATLA/RARL-style alternation over any scenario.

Each iteration reads as three named steps, as in PSRO::

    update_protagonists()   # train the protagonist vs adversaries drawn from the population
    update_adversaries()    # train each learned adversary vs the frozen protagonist
    snapshot()              # checkpoint both sides, grow the population, evaluate, log

The chain points one way: `advgame.training.config` (`TrainConfig`, `METHODS`,
`learner_config`) -> `advgame.training.trainer` (`Trainer`) -> `advgame.training.loop` (`Run`: persistence,
resume, logging) -> `advgame.training.run` (`train`, `resume`); this module re-exports the public names.

A run directory holds everything: ``config.json``, ``state.json`` (the last finished
iteration), ``checkpoints/iter_NNNN/``, ``population.json``, ``progress.csv`` and ``tb/``
(TensorBoard). Every iteration is committed atomically, so a run killed at any moment (even
by SIGKILL) loses at most the iteration in progress; `resume` continues it.
"""

from __future__ import annotations

from advgame.training.config import METHODS, TEAM_ALGOS, TrainConfig, learner_config
from advgame.training.run import resume, train
from advgame.training.trainer import Trainer

__all__ = ["METHODS", "TEAM_ALGOS", "TrainConfig", "Trainer", "learner_config", "resume", "train"]
