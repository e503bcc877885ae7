"""Observation normalizers saved beside SB3 models: the project's ``.npz`` or a `VecNormalize` pickle.

`load_normalizer` reads either into a frozen `Normalizer` (what `advgame.agents.common.checkpoint`'s
policies normalize with), cached per process and file version.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from advgame.core.files import reading
from advgame.errors import ConfigError, FileFormatError

__all__ = ["CHECKPOINT_FIX", "Normalizer", "load_normalizer"]

CHECKPOINT_FIX = (
    "Save it again from the model (or rerun the training iteration that wrote it); a copy "
    "cut short in transfer loads once copied whole."
)
"""How to recover from a damaged checkpoint or normalizer file."""


@dataclass(frozen=True)
class Normalizer:
    """Frozen observation-normalizer statistics, as SB3's `VecNormalize` applies them."""

    mean: np.ndarray
    """Running mean of the raw observations."""
    var: np.ndarray
    """Running variance of the raw observations."""
    clip_obs: float = 10.0
    """Normalized observations are clipped to ``[-clip_obs, clip_obs]``."""
    epsilon: float = 1e-8
    """Added to the variance before its square root."""


def load_normalizer(path: str) -> Normalizer | None:
    """Read a normalizer: an ``.npz`` (``mean``, ``var``) or a `VecNormalize` pickle.

    Returns None for a `VecNormalize` saved with ``norm_obs=False`` (raw observations). Cached
    per process and file version. Only load pickles you trust: unpickling runs code.
    """
    if not Path(path).is_file():
        raise ConfigError(
            f"No normalizer file at {path!r}; give the `VecNormalize.save` pickle or the "
            "``*_obs_norm.npz`` saved beside the model."
        )
    return _read_normalizer(path, Path(path).stat().st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _read_normalizer(path: str, mtime_ns: int) -> Normalizer | None:
    if path.endswith(".npz"):
        with reading(path, "observation normalizer", CHECKPOINT_FIX), np.load(path) as stats:
            if "mean" not in stats or "var" not in stats:
                raise FileFormatError(
                    f"The observation normalizer {path} holds {list(stats)}; expected 'mean' and "
                    f"'var' (written by another program?). {CHECKPOINT_FIX}",
                    path=path,
                )
            return Normalizer(np.asarray(stats["mean"]), np.asarray(stats["var"]))
    return _vecnormalize_stats(path)


def _vecnormalize_stats(path: str) -> Normalizer | None:
    import pickle

    from stable_baselines3.common.running_mean_std import RunningMeanStd

    fix = (
        "Expected a VecNormalize pickle (`VecNormalize.save`) or an .npz with 'mean' and 'var'; "
        + CHECKPOINT_FIX
    )
    with reading(path, "VecNormalize normalizer", fix), open(path, "rb") as f:
        norm = pickle.load(f)
    rms = getattr(norm, "obs_rms", None)
    if not isinstance(rms, RunningMeanStd):
        raise ConfigError(
            f"{path} holds {type(norm).__name__} with obs_rms {type(rms).__name__}; expected a "
            "VecNormalize of a Box observation space (Dict observations are not supported)."
        )
    if not getattr(norm, "norm_obs", True):
        return None
    return Normalizer(rms.mean, rms.var, float(norm.clip_obs), float(norm.epsilon))
