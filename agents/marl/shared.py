"""IPPO with parameter sharing for homogeneous protagonists: SB3 PPO on SuperSuit's agents-as-envs.

When the protagonists of a team are interchangeable (the same observation and action shapes,
and one policy may serve them all), SuperSuit turns a `TeamView` into a vector env with one
slot per protagonist, and a single Stable-Baselines3 PPO learns the shared policy: IPPO with
parameter sharing, on a maintained library (design invariant 6). The pipeline is SuperSuit's own::

    pad_observations_v0 -> pad_action_space_v0 -> pettingzoo_env_to_vec_env_v1
        -> concat_vec_envs_v1(n_envs, num_cpus=0) -> SB3 VecEnv (+ VecNormalize)

SuperSuit's agents-as-envs vectorisation forces one policy on *every* agent of the env, which is
why it only ever sees the protagonist team: the adversaries stay frozen policies inside the view.
Heterogeneous teams (different shapes or roles) train with `advgame.agents.marl.marl.TeamLearner`.

`SharedIPPO` follows the `advgame.agents.common.side.Side` protocol like `TeamLearner`; its `steps` count
team steps (SB3 counts one step per protagonist slot).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from advgame.agents.common.checkpoint import SB3Checkpoint
from advgame.agents.common.stats import EpisodeStats, normalized
from advgame.errors import ConfigError

__all__ = ["SharedIPPO", "shared_venv"]


def _sb3_adapter() -> type:
    """SuperSuit's SB3 adapter plus what Stable-Baselines3 2.x needs from it.

    SB3 seeds a VecEnv with ``seed()`` when a model is built (the adapter has none), and
    bootstraps at time limits only when ``info["TimeLimit.truncated"]`` says so (SuperSuit
    reports truncations but drops the flag SB3 reads).
    """
    from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

    class SB3SuperSuit(SB3VecEnvWrapper):
        _next_seed: int | None = None

        def seed(self, seed: int | None = None) -> list[None]:
            """Use `seed` at the next reset (slot ``i`` of the concat resets with seed + i)."""
            self._next_seed = seed
            return [None] * self.num_envs

        def reset(self, seed: int | None = None, options: dict | None = None) -> Any:
            """Reset every team (with the stored seed, once)."""
            seed, self._next_seed = (seed if seed is not None else self._next_seed), None
            observations, self.reset_infos = self.venv.reset(seed=seed, options=options)
            return observations

        def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
            """``render_mode`` per slot (SB3 asks for it; SuperSuit's vector env has no get_attr)."""
            if attr_name != "render_mode":
                raise AttributeError(f"SuperSuit's vector env does not expose {attr_name!r}.")
            return [self.render_mode] * self.num_envs

        def step_wait(self) -> tuple[Any, Any, Any, Any]:
            """SuperSuit's step, with SB3's truncation flag in each info."""
            observations, rewards, terms, truncs, infos = self.venv.step_wait()
            for i, info in enumerate(infos):
                info["TimeLimit.truncated"] = bool(truncs[i] and not terms[i])
            return observations, rewards, np.logical_or(terms, truncs), infos

    return SB3SuperSuit


def shared_venv(env_fn: Callable[[], Any], n_envs: int = 1) -> Any:
    """An SB3 VecEnv with one slot per protagonist of `n_envs` copies of the team view `env_fn` builds.

    SuperSuit builds the copies by pickling the first view (in this process, ``num_cpus=0``).
    """
    import supersuit as ss

    team = env_fn()
    shapes = {
        (team.observation_space(a).shape, team.action_space(a).shape) for a in team.possible_agents
    }
    if len(shapes) != 1:
        raise ConfigError(
            f"SharedIPPO shares one policy, so every protagonist needs the same observation and "
            f"action shapes; {team!r} has {sorted(shapes)}. Train heterogeneous teams with "
            "advgame.agents.marl.marl.TeamLearner(IPPOConfig() or MAPPOConfig(), ...)."
        )
    padded = ss.pad_action_space_v0(ss.pad_observations_v0(team))
    vec = ss.pettingzoo_env_to_vec_env_v1(padded)
    return _sb3_adapter()(ss.concat_vec_envs_v1(vec, n_envs, num_cpus=0, base_class="gymnasium"))


class SharedIPPO:
    """One SB3 PPO policy shared by every protagonist of a team (parameter-sharing IPPO).

    Args:
        config: an `advgame.agents.PPOConfig` (the paper's table).
        env_fn: a thunk building a `TeamView` (`advgame.core.team.team_factory`).
        seed: seeds SB3 (which seeds torch and numpy globally) and the team views.
        total_steps: planned team steps of the run (for the learning-rate decay).
        n_envs: team views stepped in sync in this process.
        normalize: `VecNormalize` observations and rewards (one normalizer for all slots).
        tensorboard_log: a folder for SB3's TensorBoard scalars, or None.

    """

    def __init__(
        self,
        config: Any,
        env_fn: Callable[[], Any],
        seed: int,
        total_steps: int,
        n_envs: int = 1,
        normalize: bool = True,
        tensorboard_log: str | None = None,
        venv: Any = None,
        model: Any = None,
    ) -> None:
        from stable_baselines3.common.vec_env import VecNormalize

        self.config = config
        if venv is None:
            venv = normalized(shared_venv(env_fn, n_envs), normalize, config.gamma)
        self.venv = venv
        self.normalized = isinstance(venv, VecNormalize)
        self.agents: list[str] = list(self._views()[0].possible_agents)
        n = len(self.agents)
        self.model = model or config.make_model(venv, seed, total_steps * n, tensorboard_log)

    @property
    def steps(self) -> int:
        """Team steps trained on (SB3's step count divided by the team size)."""
        return int(self.model.num_timesteps) // len(self.agents)

    def learn(self, steps: int, stats: EpisodeStats | None = None) -> None:
        """Train for (at least) `steps` more team steps; true team returns go to `stats`."""
        n = len(self.agents)
        decay = self.model.learning_rate
        if callable(decay) and hasattr(decay, "offset"):  # a run-long LinearDecay
            decay.offset, decay.span = self.model.num_timesteps, steps * n
        if self.normalized:
            self.venv.training = True
        callback = _team_callback(stats, n) if stats is not None else None
        self.model.learn(
            steps * n, reset_num_timesteps=False, callback=callback, progress_bar=False
        )

    def freeze(self) -> None:
        """Stop updating the observation normalizer."""
        if self.normalized:
            self.venv.training = False

    def set_policies(self, policies: Mapping[str, Any], index: int | None = None) -> None:
        """Replace embedded adversary policies in every team view (or view `index`)."""
        views = self._views()
        for view in views if index is None else [views[index]]:
            view.set_policies(dict(policies))

    def set_observation_scale(self, target: str, std: np.ndarray) -> None:
        """Pass a protagonist's normalizer std to normalized-space observation disruptors."""
        for view in self._views():
            view.set_observation_scale(target, std)

    def observation_std(self) -> dict[str, np.ndarray] | None:
        """The shared normalizer's std, per protagonist (None if unnormalized)."""
        if not self.normalized:
            return None
        std = np.sqrt(self.venv.obs_rms.var + self.venv.epsilon)
        return {a: std.copy() for a in self.agents}

    def save(self, folder: Path, deterministic: bool = True) -> dict[str, SB3Checkpoint]:
        """Write the model (and normalizer); the same `SB3Checkpoint` spec for every protagonist."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / "shared_ippo.zip"
        self.model.save(path)
        normalizer = None
        if self.normalized:
            normalizer = folder / "shared_ippo_obs_norm.npz"
            np.savez(normalizer, mean=self.venv.obs_rms.mean, var=self.venv.obs_rms.var)
            self.venv.save(folder / "shared_ippo_vecnormalize.pkl")
        spec = SB3Checkpoint(
            str(path), "ppo", str(normalizer) if normalizer else None, deterministic
        )
        return dict.fromkeys(self.agents, spec)

    @classmethod
    def load(
        cls, folder: Path, config: Any, env_fn: Callable[[], Any], n_envs: int = 1
    ) -> SharedIPPO:
        """Rebuild a learner saved by `save` (to resume a run)."""
        from stable_baselines3 import PPO
        from stable_baselines3.common.vec_env import VecNormalize

        folder = Path(folder)
        venv = shared_venv(env_fn, n_envs)
        stats = folder / "shared_ippo_vecnormalize.pkl"
        if stats.exists():
            venv = VecNormalize.load(str(stats), venv)
        model = PPO.load(folder / "shared_ippo.zip", env=venv, device="cpu")
        return cls(config, env_fn, 0, 1, venv=venv, model=model)

    def close(self) -> None:
        """Close the team views."""
        self.venv.close()

    def _views(self) -> list[Any]:
        """The `TeamView`s inside the vectorisation (reachable because it runs in-process)."""
        inner = self.venv
        while not hasattr(inner, "vec_envs"):  # VecNormalize -> adapter -> ConcatVecEnv
            inner = inner.venv
        return [markov.par_env.unwrapped for markov in inner.vec_envs]


def _team_callback(stats: EpisodeStats, n_agents: int) -> Any:
    """Record one true team return per finished episode (from each team's first slot)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class TeamStats(BaseCallback):
        def _init_callback(self) -> None:
            self._acc = np.zeros(self.training_env.num_envs // n_agents)

        def _on_step(self) -> bool:
            infos, dones = self.locals["infos"], self.locals["dones"]
            for team in range(len(self._acc)):
                slot = team * n_agents
                self._acc[team] += infos[slot].get("true_reward", 0.0)
                if dones[slot]:
                    stats.true_returns.append(float(self._acc[team]))
                    self._acc[team] = 0.0
            if stats.progress is not None:
                stats.progress.update(len(self._acc))
            return True

    return TeamStats()
