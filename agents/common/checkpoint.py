"""Stable-Baselines3 checkpoints as policies: what populations store and evaluation loads.

A checkpoint is a ``.zip`` saved by an SB3 model plus, optionally, the observation normalizer
the policy was trained behind: the project's ``*_obs_norm.npz`` (``mean`` and ``var``) or a
`VecNormalize` pickle saved by plain SB3 (``VecNormalize.save``), read by `load_normalizer`.
`SB3Checkpoint` is the picklable spec that rebuilds it as a `Policy` in any process:
`advgame.agents.common.sb3_policy.SB3Policy`, or `advgame.agents.common.recurrent_policy.RecurrentSB3Policy`
for an LSTM policy (both importable from here too).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from advgame.agents.common.normalizer import CHECKPOINT_FIX, Normalizer, load_normalizer
from advgame.agents.common.recurrent_policy import RecurrentSB3Policy
from advgame.agents.common.sb3_policy import SB3Policy
from advgame.core.files import reading
from advgame.core.policy import AgentInfo
from advgame.core.registry import load
from advgame.errors import ConfigError

__all__ = [
    "ALGOS",
    "Normalizer",
    "RecurrentSB3Policy",
    "SB3Checkpoint",
    "SB3Policy",
    "load_model",
    "load_normalizer",
    "saved_recurrent",
]

_LEARNERS = "advgame.agents.learners:LEARNERS"

ALGOS = ("ppo", "sac", "td3", "ompo", "dbc", "rsc", "recurrent-ppo")


def _algo_class(algo: str) -> Any:
    """The SB3 class that loads a checkpoint of `algo`.

    SB3's own for PPO, SAC and TD3; otherwise the class its learner config trains
    (``model_class``: OMPO, DBC, RSC, sb3-contrib's RecurrentPPO), so a new learner registers
    in one place. The registry of configs sits above the common room (it names every family):
    it is looked up by its entry point, as `advgame.training.TrainConfig` does.
    """
    import stable_baselines3 as sb3

    if algo not in ALGOS:
        raise ConfigError(f"Unknown algorithm {algo!r}; expected one of {ALGOS}.")
    classes = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}
    return classes[algo] if algo in classes else load(_LEARNERS)[algo].model_class()


@functools.lru_cache(maxsize=64)
def load_model(path: str, algo: str) -> Any:
    """Load an SB3 model on the CPU (cached per process: evaluation reuses it across cells).

    A policy is loaded to act, not to train on: a HER replay buffer (which SB3 can build only
    with an env) is replaced by the plain one, so HER checkpoints load without their env.
    """
    if not Path(path).exists():
        raise ConfigError(f"No checkpoint at {path!r}.")
    plain: dict[str, Any] = {
        "replay_buffer_class": None,
        "replay_buffer_kwargs": {},
    }  # only where saved (SAC/TD3)
    recurrent = saved_recurrent(path)
    if recurrent is not None and recurrent != (algo == "recurrent-ppo"):
        saved = "RecurrentPPO's LSTM policy" if recurrent else "a feed-forward policy"
        raise ConfigError(
            f"{path} holds {saved}, not a {algo} model; load it as "
            f"{'recurrent-ppo' if recurrent else 'the algorithm that saved it (ppo, sac, ...)'} "
            f"(--checkpoint NAME=PATH:{'recurrent-ppo' if recurrent else 'ppo'})."
        )
    cls = _algo_class(algo)
    with reading(path, f"{algo.upper()} checkpoint", CHECKPOINT_FIX):
        return cls.load(path, device="cpu", custom_objects=plain)


def saved_recurrent(path: str) -> bool | None:
    """Whether the SB3 zip at `path` saved an sb3-contrib recurrent policy (None: unreadable).

    Read from the zip's ``data`` record (the policy class's module), without loading torch, so
    a caller can pick ``algo="recurrent-ppo"`` or ``"ppo"`` before loading.

    Example:
        ``SB3Checkpoint(path, "recurrent-ppo" if saved_recurrent(path) else "ppo")``

    """
    import json
    import zipfile

    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
        module = data["policy_class"]["__module__"]
    except (OSError, KeyError, TypeError, ValueError, zipfile.BadZipFile):
        return None  # the load itself reports a damaged file
    return "sb3_contrib.common.recurrent" in str(module)


@dataclass(frozen=True)
class SB3Checkpoint:
    """A saved SB3 model (and normalizer) as a picklable policy spec.

    Example:
        ``SB3Checkpoint("runs/demo/checkpoints/iter_0004/protagonist.zip", algo="ppo")``

    """

    path: str
    """The model ``.zip``."""
    algo: str = "ppo"
    """How it was trained: one of `ALGOS` (``"ppo"``, ``"sac"``, ``"td3"``, ``"ompo"``, ``"dbc"``,
    ``"rsc"``, ``"recurrent-ppo"``: an sb3-contrib LSTM policy, which carries its memory)."""
    normalizer: str | None = None
    """The observation normalizer, if any: an ``.npz`` with ``mean`` and ``var`` or a
    `VecNormalize` pickle (see `load_normalizer`)."""
    deterministic: bool = True
    """Act with the mode of the action distribution."""

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ConfigError(f"SB3Checkpoint.algo must be one of {ALGOS}, got {self.algo!r}.")

    def build(self, info: AgentInfo) -> SB3Policy:
        """Load the model and normalizer (cached per process); check they fit `info`'s spaces."""
        model = load_model(str(self.path), self.algo)
        for what in ("observation", "action"):
            have, want = getattr(model, f"{what}_space"), getattr(info, f"{what}_space")
            if have.shape != want.shape or type(have) is not type(want):
                raise ConfigError(
                    f"Checkpoint {self.path} has {what} space {have}, but {info.agent!r} has "
                    f"{want}; evaluate it on a scenario with the spaces it was trained on."
                )
        norm = load_normalizer(str(self.normalizer)) if self.normalizer is not None else None
        kind = RecurrentSB3Policy if self.algo == "recurrent-ppo" else SB3Policy  # LSTM: memory
        if norm is None:
            return kind(model, deterministic=self.deterministic)
        if norm.mean.shape != info.observation_space.shape:
            raise ConfigError(
                f"The normalizer {self.normalizer} has shape {norm.mean.shape}, but "
                f"{info.agent!r} observes {info.observation_space.shape}; give the normalizer "
                f"saved with {self.path}."
            )
        return kind(model, norm.mean, norm.var, self.deterministic, norm.clip_obs, norm.epsilon)
