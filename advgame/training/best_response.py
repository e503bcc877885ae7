"""Best-response training as a job: one learner against a fixed mixture of opponents.

A `BestResponseJob` is a pure, picklable value; `train_best_response` trains its learner
(`advgame.agents.common.side.Side`, an SB3 model on a `SingleAgentView`) against a
`MixtureSpec` of the other side's policies and returns the checkpoint *as bytes*, so the job
can run on any worker of any node (`advgame.runner.run.run_units`) and the driver
writes the files where the run keeps them. `advgame.workflows.psro` builds these jobs.
"""

from __future__ import annotations

import json
import logging
import shutil
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from advgame.core.config import write_atomic
from advgame.core.files import read_json
from advgame.core.policy import WhiteBox, WhiteBoxForwarder, as_policy
from advgame.core.progress import report
from advgame.core.scratch import scratch
from advgame.errors import ConfigError, FileFormatError

__all__ = [
    "BestResponseJob",
    "MixturePolicy",
    "MixtureSpec",
    "best_response_side",
    "split_n_envs",
    "train_best_response",
]

log = logging.getLogger(__name__)

_CHUNKS = 4
"""A learner behind a normalizer trains in this many chunks, its normalized-space budgets
given the normalizer's current std before each (as the alternation loop does per phase)."""

_SAVES = 16
"""A resumable best response saves its learner about this many times (`train_best_response`)."""

_STATE = "state.json"
"""The file in a best response's scratch folder naming its last whole save and its steps."""


class MixturePolicy:
    """Plays one of its policies per episode, drawn with the mixture's weights at each reset."""

    def __init__(self, policies: list[Any], weights: np.ndarray, seed: int) -> None:
        self.policies, self.weights = policies, weights
        self.rng = np.random.default_rng(seed)
        self.current = policies[0]

    @property
    def wrapped(self) -> Any:
        """The policy playing this episode."""
        return self.current

    def __getattr__(self, name: str) -> Any:  # e.g. observation_std of the drawn checkpoint
        return getattr(self.__dict__.get("current"), name)

    def reset(self, seed: int | None = None) -> None:
        """Draw this episode's policy (a seed restarts the draws) and reset it."""
        if seed is not None:
            self.rng = np.random.default_rng([seed, 7919])
        self.current = self.policies[int(self.rng.choice(len(self.policies), p=self.weights))]
        self.current.reset(seed)

    def act(self, observation: Any) -> Any:
        """Act as this episode's policy."""
        return self.current.act(observation)


class _WhiteBoxMixture(MixturePolicy, WhiteBoxForwarder):
    """A mixture of white-box policies: a `WhiteBox` on every Python (3.12+ checks statically)."""


@dataclass(frozen=True)
class MixtureSpec:
    """A meta-strategy as a policy spec: specs and their probabilities (one draw per episode)."""

    specs: tuple[Any, ...]
    """The members' policy specs."""
    weights: tuple[float, ...]
    """Their probabilities (>= 0, summing to 1)."""
    seed: int = 0
    """Seeds the draws."""

    def __post_init__(self) -> None:
        w = np.asarray(self.weights, dtype=float)
        if len(self.specs) != len(w) or not self.specs:
            raise ConfigError(
                f"A mixture needs one weight per spec, got {len(w)} for {len(self.specs)}."
            )
        if w.min() < 0 or abs(w.sum() - 1) > 1e-6:
            raise ConfigError(f"Mixture weights must be >= 0 and sum to 1, got {self.weights}.")

    def build(self, info: Any) -> MixturePolicy:
        """Build every member's policy for `info`'s agent (a `WhiteBox` if every one is)."""
        w = np.asarray(self.weights, dtype=float)
        policies = [as_policy(s, info) for s in self.specs]
        white = all(isinstance(p, WhiteBox) for p in policies)
        return (_WhiteBoxMixture if white else MixturePolicy)(policies, w / w.sum(), self.seed)


@dataclass(frozen=True, kw_only=True)
class BestResponseJob:
    """Train `agent` for `steps` against `opponents` (a mixture of the other side's policies)."""

    name: str
    """The member id the result becomes (e.g. ``"protagonist@2"``)."""
    scenario: str
    """Registered scenario id."""
    make_kwargs: Mapping[str, Any] = field(default_factory=dict)
    """`advgame.make` options (``preset=``, task options); ``phase`` is ``"train"``."""
    agent: str
    """The learner's agent id."""
    algo: str = "ppo"
    """Its learner (`advgame.training.learner_config`)."""
    hparams: Mapping[str, Any] | None = None
    """Learner config overrides; ``n_envs`` (views trained on at once, default 1) is read here
    and not passed to the learner."""
    opponents: Mapping[str, MixtureSpec]
    """``{agent id: mixture}`` of the agents it plays against."""
    steps: int
    """Environment steps to train."""
    seed: int = 0
    """Seeds the model, the views and the mixture draws."""
    normalize: bool = True
    """Train behind a `VecNormalize` (observations and rewards)."""


def split_n_envs(hparams: Mapping[str, Any] | None, owner: str) -> tuple[int, dict[str, Any]]:
    """``(n_envs, the learner config's overrides)`` from a best response's `hparams`.

    ``n_envs`` (views trained on at once, default 1) is the job's, not the learner's; `owner`
    names where the hparams come from in the error (an `OptimalSearch` grid checks its entries
    with it before any job runs).
    """
    rest = dict(hparams or {})
    n_envs = rest.pop("n_envs", 1)
    if type(n_envs) is not int or n_envs < 1:
        raise ConfigError(f"{owner}: n_envs must be an int >= 1, got {n_envs!r}.")
    return n_envs, rest


def _normalized_targets(job: BestResponseJob) -> list[str]:
    from advgame.core.registry import make

    game = make(job.scenario, **job.make_kwargs)
    game.close()
    return game.scaled_targets


def _opponent_std(job: BestResponseJob) -> np.ndarray | None:
    """The std of the most likely opponent checkpoint's normalizer (None without one)."""
    from advgame.agents.common.checkpoint import load_normalizer

    for mix in job.opponents.values():
        spec = mix.specs[int(np.argmax(mix.weights))]
        path = getattr(spec, "normalizer", None)
        norm = load_normalizer(str(path)) if path else None
        if norm is not None:
            return np.sqrt(norm.var + norm.epsilon)
    return None


def best_response_side(
    job: BestResponseJob, folder: Path | None = None
) -> tuple[Any, Callable[[], None], int]:
    """The job's learner as a `Side` and the call that sets its budgets before each chunk.

    Args:
        job: the best response to train.
        folder: a folder a `Side.save` of this job wrote, to continue from (None: a new side).

    Returns:
        ``(side, rescale, chunks)``: ``rescale()`` gives the scenario's normalized-space
        budgets the victim's normalizer std (the learner's own, as it stands, where the
        learner is the victim; else the most likely opponent checkpoint's, fixed), as the
        alternation loop does per phase: call it before each `Side.learn`. ``chunks``: how
        many `Side.learn` calls the job's steps take (`_CHUNKS` where the learner is a
        normalized victim, whose std moves as it learns; else 1).

    """
    import torch

    from advgame.agents.common.side import Side
    from advgame.core.views import view_factory
    from advgame.training.config import learner_config

    torch.set_num_threads(1)
    n_envs, hparams = split_n_envs(job.hparams, f"Best response {job.name}")
    learner = learner_config(job.algo, hparams)
    kwargs = {**job.make_kwargs, "phase": "train"}
    fns = [view_factory(job.scenario, job.agent, dict(job.opponents), **kwargs)] * n_envs
    targets = _normalized_targets(job)
    if folder is None:
        side = Side(job.agent, learner, fns, job.seed, job.steps, normalize=job.normalize)
    else:
        side = Side.load(folder, job.agent, learner, fns)
    learner_is_victim = job.agent in targets
    fixed = None if learner_is_victim else _opponent_std(job)

    def rescale() -> None:
        std = side.observation_std() if learner_is_victim else fixed
        if std is not None:
            for target in targets:
                side.set_observation_scale(target, std)

    chunked = bool(targets) and learner_is_victim and side.normalized
    return side, rescale, _CHUNKS if chunked else 1


def _saved(folder: Path | None) -> tuple[Path | None, int]:
    """The last whole save in a scratch `folder` and the job's steps it holds ((None, 0): none)."""
    state = folder / _STATE if folder is not None else None
    if state is None or not state.exists():
        return None, 0
    fix = f"Delete {state.parent}: the job then trains from its first step."
    data = read_json(state, "best-response save", fix, dict)
    if data.get("slot") not in ("a", "b") or not isinstance(data.get("steps"), int):
        raise FileFormatError(
            f"{state} should name a slot and steps, got {data!r}. {fix}", path=str(state)
        )
    return state.parent / data["slot"], data["steps"]


def _save(side: Any, folder: Path, done: int) -> None:
    """Save `side` into the slot the state file does not name, then name it (a kill: either)."""
    last, _ = _saved(folder)
    slot = folder / ("b" if last is not None and last.name == "a" else "a")
    shutil.rmtree(slot, ignore_errors=True)
    side.save(slot)
    write_atomic(folder / _STATE, json.dumps({"slot": slot.name, "steps": done}) + "\n")


def _save_every(side: Any, steps: int) -> int | None:
    """Steps between saves: a whole number of rollouts near ``steps / _SAVES`` (None: no saves).

    On-policy learners only: the same rollouts and updates as one ``learn`` call, and nothing
    but the model and normalizer to save (an off-policy learner's replay buffer is the run).
    """
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

    if not isinstance(side.model, OnPolicyAlgorithm):  # off-policy ones have n_steps too (n-step)
        return None
    rollout = int(side.model.n_steps) * int(side.model.n_envs)
    return max(rollout, steps // _SAVES // rollout * rollout)


def train_best_response(job: BestResponseJob) -> dict[str, Any]:
    """Train the job's learner; return ``{"files": {name: bytes}, "model", "normalizer", "algo"}``.

    Where the runner gives the job a scratch folder (`advgame.core.scratch`: a run that keeps
    part files, on the local executor), an on-policy learner is saved there about `_SAVES`
    times, at rollout boundaries (so the updates are those of one uninterrupted ``learn``), and
    a job run again after an interruption goes on from its last save.
    """
    folder = scratch()
    slot, done = _saved(folder)
    try:
        side, rescale, chunks = best_response_side(job, slot)
    except Exception as exc:
        if slot is None or folder is None:
            raise
        # a save that no longer loads (its files removed, written by another version): start
        # over rather than fail every retry on the same save
        log.warning("best response %s: its save in %s does not load (%s: %s); training from "
                    "the start", job.name, folder, type(exc).__name__, exc)  # fmt: skip
        shutil.rmtree(folder, ignore_errors=True)
        slot, done = None, 0
        side, rescale, chunks = best_response_side(job)
    if slot is not None:
        log.info("best response %s: going on from its save at %d steps", job.name, done)
    try:
        every = _save_every(side, job.steps) if folder is not None else None
        for k in range(chunks):
            end = job.steps * (k + 1) // chunks
            if done >= end:
                continue
            rescale()
            while done < end:
                part = end - done if every is None else min(every, end - done)
                side.learn(part)
                done += part
                report(part)  # a bar counting steps moves inside the job (in this process)
                if folder is not None and every is not None and done < job.steps:
                    _save(side, folder, done)
        with tempfile.TemporaryDirectory(prefix="advgame-br-") as tmp:
            spec = side.save(Path(tmp))
            files = {p.name: p.read_bytes() for p in Path(tmp).iterdir() if p.is_file()}
    finally:
        side.close()
    log.info("best response %s: %d steps", job.name, side.steps)
    return {
        "files": files,
        "model": Path(spec.path).name,
        "normalizer": Path(spec.normalizer).name if spec.normalizer else None,
        "algo": spec.algo,
    }
