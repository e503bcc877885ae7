"""One learning agent: its views of a game, its normalizer and its SB3 model.

A `Side` owns a VecEnv of `SingleAgentView`s of one agent (protagonist or adversary): a
`VectorView` in this process or a `SubprocVecEnv`; an optional `VecNormalize`; and the Stable-Baselines3 model that learns on them. The loop swaps
the frozen opponents inside the views between phases (`Side.set_policies`), trains for a
number of steps (`Side.learn`), and checkpoints (`Side.save`, `Side.load`).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.agents.common.stats import EpisodeStats, normalized
from advgame.core.files import read_json
from advgame.errors import FileFormatError

__all__ = ["Side"]

log = logging.getLogger(__name__)


def _make_venv(env_fns: Sequence[Callable[[], Any]], vec_env: str) -> Any:
    """In-process views in lockstep (`VectorView`: opponents batched), or one process per view.

    Training rollouts need the distribution of episodes, not bit-for-bit replays of single
    views, so a frozen LSTM opponent's copies share one forward pass (``exact=False``).
    """
    from stable_baselines3.common.vec_env import SubprocVecEnv

    from advgame.core.vector import VectorView

    if vec_env == "subproc" and len(env_fns) > 1:
        return SubprocVecEnv(list(env_fns), start_method="forkserver")
    return VectorView(list(env_fns), exact=False)


class Side:
    """One learning agent: views of `agent`, an optional normalizer, and its SB3 model.

    Args:
        agent: the agent id it learns for.
        learner: a learner config (`advgame.agents.PPOConfig`, ...).
        env_fns: thunks building its views (`advgame.core.views.view_factory`).
        seed: seeds the model and the VecEnv.
        total_steps: planned steps over the run (for learning-rate decay).
        normalize: wrap the views in `VecNormalize` (observations and rewards).
        tensorboard_log: a folder for SB3's TensorBoard scalars, or None.
        vec_env: ``"dummy"``: the views in this process, stepped in lockstep by
            `advgame.core.vector.VectorView` (frozen opponents called once per step for all
            views; fastest for cheap task bases on few cores), or ``"subproc"``: one
            `SubprocVecEnv` worker per view (heavy task bases, many cores).

    """

    def __init__(
        self,
        agent: str,
        learner: Any,
        env_fns: Sequence[Callable[[], Any]],
        seed: int,
        total_steps: int,
        normalize: bool = True,
        tensorboard_log: str | None = None,
        vec_env: str = "dummy",
        model: Any = None,
        venv: Any = None,
    ) -> None:
        from stable_baselines3.common.vec_env import VecNormalize

        self.agent = agent
        self.learner = learner
        if venv is None:
            venv = normalized(_make_venv(env_fns, vec_env), normalize, learner.gamma)
        self.venv = venv
        self.normalized = isinstance(venv, VecNormalize)
        self.model = model or learner.make_model(venv, seed, total_steps, tensorboard_log)
        if model is None:
            self.venv.seed(seed)
        self._bind()

    def _bind(self) -> None:
        """Give in-process views the live model, so attacks on the learner can read it."""
        from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

        base = self.venv.venv if isinstance(self.venv, VecNormalize) else self.venv
        if not isinstance(base, SubprocVecEnv):  # worker processes cannot see this model
            base.env_method("bind_learner", self.model, self.venv if self.normalized else None)

    @property
    def steps(self) -> int:
        """Environment steps this side has trained on."""
        return int(self.model.num_timesteps)

    def learn(self, steps: int, stats: EpisodeStats | None = None) -> None:
        """Train for (at least) `steps` more environment steps, normalizer updating."""
        decay = self.model.learning_rate
        if callable(decay) and hasattr(decay, "offset"):  # a run-long LinearDecay
            decay.offset, decay.span = self.steps, steps
        if self.normalized:
            self.venv.training = True
        callback = stats.callback() if stats is not None else None
        self.model.learn(
            steps,
            reset_num_timesteps=False,
            callback=callback,
            progress_bar=False,
            tb_log_name=self.agent,
        )

    def freeze(self) -> None:
        """Stop updating the observation normalizer (while the other side trains)."""
        if self.normalized:
            self.venv.training = False

    def set_policies(self, policies: Mapping[str, Any], index: int | None = None) -> None:
        """Replace embedded opponent policies in every view (or view `index`)."""
        self.venv.env_method("set_policies", dict(policies), indices=index)

    def set_observation_scale(self, target: str, std: np.ndarray) -> None:
        """Pass a normalizer std to the views' normalized-space observation disruptors."""
        self.venv.env_method("set_observation_scale", target, std)

    def observation_std(self) -> np.ndarray | None:
        """The current std of this side's observation normalizer (None if unnormalized)."""
        if not self.normalized:
            return None
        rms = self.venv.obs_rms
        return np.sqrt(rms.var + self.venv.epsilon)

    def save(self, folder: Path, deterministic: bool = True) -> SB3Checkpoint:
        """Write model, normalizer stats and state; return the spec that replays the policy."""
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{self.agent}.zip"
        self.model.save(path)
        normalizer = None
        if self.normalized:
            normalizer = folder / f"{self.agent}_obs_norm.npz"
            np.savez(normalizer, mean=self.venv.obs_rms.mean, var=self.venv.obs_rms.var)
            self.venv.save(folder / f"{self.agent}_vecnormalize.pkl")
        if hasattr(self.model, "replay_buffer"):
            self.model.save_replay_buffer(folder / f"{self.agent}_replay.pkl")
        positions = self.venv.env_method("schedule_positions")
        if any(positions):  # per-episode schedules in the views: where each one is
            (folder / f"{self.agent}_schedules.json").write_text(json.dumps(positions) + "\n")
        return SB3Checkpoint(
            str(path),
            self.learner.algo,
            str(normalizer) if normalizer else None,
            deterministic=deterministic,
        )

    @classmethod
    def load(
        cls,
        folder: Path,
        agent: str,
        learner: Any,
        env_fns: Sequence[Callable[[], Any]],
        vec_env: str = "dummy",
        tensorboard_log: str | None = None,
    ) -> Side:
        """Rebuild a side saved by `save` (to resume a run)."""
        from stable_baselines3.common.vec_env import VecNormalize

        from advgame.agents.common.checkpoint import _algo_class

        venv = _make_venv(env_fns, vec_env)
        stats = folder / f"{agent}_vecnormalize.pkl"
        if stats.exists():
            venv = VecNormalize.load(str(stats), venv)
        model_class = getattr(learner, "model_class", None)
        cls_ = model_class() if model_class is not None else _algo_class(learner.algo)
        model = cls_.load(
            folder / f"{agent}.zip", env=venv, device="cpu", tensorboard_log=tensorboard_log
        )
        replay = folder / f"{agent}_replay.pkl"
        if replay.exists():
            model.load_replay_buffer(replay)
        side = cls(agent, learner, env_fns, 0, 0, model=model, venv=venv)
        schedules = folder / f"{agent}_schedules.json"
        if schedules.exists():  # the views' schedules go on after the saved episodes
            fix = "Delete the run's last checkpoint folder, or train the run again."
            positions = read_json(schedules, "schedule positions", fix, list)
            if len(positions) != venv.num_envs or not all(isinstance(p, dict) for p in positions):
                raise FileFormatError(
                    f"{schedules} should hold the schedule positions of {venv.num_envs} "
                    f"view(s), got {positions!r}. {fix}",
                    path=str(schedules),
                )
            for index, where in enumerate(positions):
                side.venv.env_method("resume_schedules", where, indices=index)
        return side

    def close(self) -> None:
        """Close the views."""
        self.venv.close()
