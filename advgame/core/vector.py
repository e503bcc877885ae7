"""N single-agent views stepped in lockstep, with the embedded policies called once per move.

`VectorView` is an SB3 `VecEnv` of N `SingleAgentView`s of one agent (protagonist or adversary),
each with its own game and its own embedded opponent policies, exactly as a `DummyVecEnv` of the
same views. What differs is the step: every view plays the same phases as
`SingleAgentView.step` (the learner's move, the moves until its next decision, the result), but
phase by phase across all N views, and before each move the embedded policies are asked for
all views at once: the observations of every view in which agent ``a`` moves go to `act_batch`,
which makes one call (one torch forward pass for a frozen SB3 network) when the N policies of
``a`` share a `batch_key`, and one call per view otherwise (noise, whose per-view generators
keep each view's draws its own).

So every episode is the one N single views would play with the same seeds (``seed(s)`` gives
view ``i`` the seed ``s + i`` as SB3 does; autoreset, ``terminal_observation``,
``TimeLimit.truncated`` and the per-view ``clipped`` counters are `DummyVecEnv`'s), while a
learned adversary costs one forward pass per step instead of N. A single view is the N = 1
case of the same phases. ``tests/test_vector.py`` pins the equivalence. `GymVectorView` shows
the same lockstep views as a Gymnasium `VectorEnv`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from gymnasium.vector import VectorEnv
from stable_baselines3.common.vec_env import DummyVecEnv

from advgame.core.policy import act_batch
from advgame.core.views import SingleAgentView
from advgame.errors import ConfigError

__all__ = ["GymVectorView", "VectorView"]


class VectorView(DummyVecEnv):
    """An SB3 `VecEnv` of `SingleAgentView`s stepped in lockstep (see the module docstring).

    Args:
        env_fns: thunks that each build one view (`advgame.core.views.view_factory`), all of
            the same agent.

    Example:
        >>> from advgame.adversaries import GaussianAdversary
        >>> from advgame.core.views import view_factory
        >>> adv = {"observation_adversary": GaussianAdversary(std=0.1)}
        >>> fns = [view_factory("Hopper-v5", "protagonist", adv, preset="state-gauss-0.1")] * 2
        >>> venv = VectorView(fns)
        >>> venv.seed(0); venv.reset().shape
        [0, 1]
        (2, 11)

    """

    envs: list[SingleAgentView]  # type: ignore[assignment]

    def __init__(self, env_fns: Sequence[Callable[[], SingleAgentView]]) -> None:
        super().__init__(list(env_fns))
        agents = {getattr(env, "agent", None) for env in self.envs}
        if not all(isinstance(env, SingleAgentView) for env in self.envs) or len(agents) != 1:
            kinds = sorted({type(env).__name__ for env in self.envs})
            raise ConfigError(
                f"VectorView steps SingleAgentViews of one agent; got {kinds} of agents "
                f"{sorted(map(str, agents))}. Build them with view_factory(scenario, agent), "
                "or use DummyVecEnv for other envs."
            )
        self.rewards = np.zeros(self.num_envs)
        """The last step's rewards in float64 (SB3's `VecEnv` returns them as float32)."""

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict]]:
        """Step every view with its action; autoreset finished views as `DummyVecEnv` does."""
        views, actions = self.envs, self.actions
        first = _others(views)
        tallies = [view._decide(actions[i], first[i]) for i, view in enumerate(views)]
        waiting = [i for i, v in enumerate(views) if v._waiting()]
        while waiting:
            sub = [views[i] for i in waiting]
            for i, v, others in zip(waiting, sub, _others(sub), strict=True):
                v._between(others, tallies[i])
            waiting = [i for i in waiting if views[i]._waiting()]
        infos = self.buf_infos
        for i, view in enumerate(views):
            obs, reward, terminated, truncated, info = view._finish(tallies[i])
            self.buf_rews[i] = self.rewards[i] = reward
            self.buf_dones[i] = terminated or truncated
            info["TimeLimit.truncated"] = truncated and not terminated
            if self.buf_dones[i]:
                info["terminal_observation"] = obs
                obs, self.reset_infos[i] = view.reset()
            infos[i] = info
            self._save_obs(i, obs)
        # each info is a fresh dict of this step (`_finish`), so no deep copy is needed
        return self._obs_from_buf(), np.copy(self.buf_rews), np.copy(self.buf_dones), list(infos)


def _others(views: Sequence[SingleAgentView]) -> list[dict[str, Any]]:
    """The embedded policies' actions for each view's next move, batched per agent."""
    groups: dict[str, list[tuple[int, Any, Any]]] = {}
    for k, view in enumerate(views):
        observe = view.game.observe
        for agent, policy in view._players_now():
            groups.setdefault(agent, []).append((k, policy, observe(agent)))
    out: list[dict[str, Any]] = [{} for _ in views]
    for agent, rows in groups.items():
        actions = act_batch([r[1] for r in rows], [r[2] for r in rows])
        for (k, _, _), action in zip(rows, actions, strict=True):
            out[k][agent] = action
    return out


class GymVectorView(VectorEnv):
    """The same lockstep views as a Gymnasium `VectorEnv` (autoreset mode ``SAME_STEP``).

    A thin face over a `VectorView`: ``reset(seed=s)`` seeds view ``i`` with ``s + i`` (as
    `gymnasium.vector.SyncVectorEnv` does), ``step`` returns Gymnasium's five batched values,
    and a finished episode's last observation and info are in ``infos["final_obs"]`` and
    ``infos["final_info"]`` while the returned observation already starts the next episode.

    Example:
        >>> from advgame.core.views import view_factory
        >>> envs = GymVectorView([view_factory("Hopper-v5", "protagonist")] * 3)
        >>> obs, infos = envs.reset(seed=0)
        >>> obs.shape, envs.single_action_space.shape
        ((3, 11), (3,))

    """

    def __init__(self, env_fns: Sequence[Callable[[], SingleAgentView]]) -> None:
        from gymnasium.vector import AutoresetMode
        from gymnasium.vector.utils import batch_space

        self.vector = VectorView(env_fns)
        view = self.vector.envs[0]
        self.num_envs = self.vector.num_envs
        self.single_observation_space = view.observation_space
        self.single_action_space = view.action_space
        self.observation_space = batch_space(view.observation_space, self.num_envs)
        self.action_space = batch_space(view.action_space, self.num_envs)
        self.metadata = {**view.metadata, "autoreset_mode": AutoresetMode.SAME_STEP}
        self.render_mode = view.render_mode

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every view (view ``i`` with ``seed + i``, or ``seed[i]``)."""
        seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else seed
        infos: dict[str, Any] = {}
        rows = []
        for i, view in enumerate(self.vector.envs):
            obs, info = view.reset(seed=None if seeds is None else seeds[i], options=options)
            rows.append(obs)
            infos = self._add_info(infos, info, i)
        return np.stack(rows), infos

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Step every view; Gymnasium's ``(obs, rewards, terminations, truncations, infos)``."""
        obs, _, dones, step_infos = self.vector.step(np.asarray(actions))
        truncated = np.array([bool(i.pop("TimeLimit.truncated")) for i in step_infos])
        terminated = dones & ~truncated
        infos: dict[str, Any] = {}
        for i, info in enumerate(step_infos):
            if dones[i]:
                final = {"final_obs": info.pop("terminal_observation"), "final_info": info}
                infos = self._add_info(infos, final, i)
                info = self.vector.reset_infos[i]
            infos = self._add_info(infos, info, i)
        return obs, self.vector.rewards.copy(), terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        """Close the views."""
        self.vector.close()
