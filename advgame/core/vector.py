"""N single-agent views stepped in lockstep, with the embedded policies called once per move.

`VectorView` is an SB3 `VecEnv` of N `SingleAgentView`s of one agent (protagonist or adversary),
each with its own game and its own embedded opponent policies, exactly as a `DummyVecEnv` of the
same views. What differs is the step: the views move phase by phase together (the learner's
move, the moves until its next decision, the result, as in `SingleAgentView.step`), split into
groups about to make the same move (`advgame.core.lockstep.groups`). Before each move the
embedded policies are asked for the whole group at once: the observations of every view in
which agent ``a`` moves go to `act_batch`, which makes one call (one torch forward pass for a
frozen SB3 network) when the policies of ``a`` share a `batch_key`, and one call per view
otherwise (noise, whose per-view generators keep each view's draws its own). When the views'
games are alike (one scenario and set-up) the group's move is made by
`advgame.core.lockstep.play_all`: each adversary's actions decoded, the perturbations applied
and the protagonist's actions checked once over ``[N, ...]``; otherwise game by game.

So every episode is the one N single views would play with the same seeds (``seed(s)`` gives
view ``i`` the seed ``s + i`` as SB3 does; autoreset, ``terminal_observation``,
``TimeLimit.truncated`` and the per-view ``clipped`` counters are `DummyVecEnv`'s), while a
learned adversary costs one forward pass per step instead of N. A single view is the N = 1
case of the same phases. ``tests/test_vector.py`` pins the equivalence. With
``exact=False`` (the training loop's choice) the copies of a frozen LSTM opponent are asked in
one batched pass too, whose rows may differ from play alone in the last bit: the same
distribution of episodes, not the same episodes. `GymVectorView` shows
the same lockstep views as a Gymnasium `VectorEnv`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from gymnasium.vector import VectorEnv
from stable_baselines3.common.vec_env import DummyVecEnv

from advgame.core import lockstep
from advgame.core.game import Move
from advgame.core.policy import act_batch
from advgame.core.vector_array import ArrayPath, array_path
from advgame.core.views import SingleAgentView
from advgame.errors import ConfigError

__all__ = ["GymVectorView", "VectorView"]


class VectorView(DummyVecEnv):
    """An SB3 `VecEnv` of `SingleAgentView` views stepped in lockstep (see the module docstring).

    Args:
        env_fns: thunks that each build one view (`advgame.core.views.view_factory`), all of
            the same agent.
        exact: keep every episode bit for bit the one a single view plays (True); False lets
            a recurrent opponent's copies share one forward pass (`act_batch`'s ``exact``).
        array: play the views as one `ArrayGame` where they allow it
            (`advgame.core.vector_array`); False keeps the lockstep path (benchmarks).

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

    def __init__(
        self,
        env_fns: Sequence[Callable[[], SingleAgentView]],
        exact: bool = True,
        array: bool = True,
    ) -> None:
        super().__init__(list(env_fns))
        self.exact = exact
        """Whether each episode is exactly a single view's (see the module docstring)."""
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
        self.agent: str = self.envs[0].agent
        """The agent whose view this is."""
        self._games = [view.game for view in self.envs]
        self._alike = lockstep.alike(self._games)  # else each game plays its own moves
        self._box = list(self.buf_obs) == [None]
        self.array = array
        """Whether the views may be played as one `ArrayGame`."""
        self._array: ArrayPath | None = array_path(self.envs, exact) if array else None
        """The views as one `ArrayGame` where they can be (`advgame.core.vector_array`)."""

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list[Any]:
        """`DummyVecEnv.env_method`; new embedded policies may change the path the views take.

        A policy bound to its game (a white-box attack) cannot play on the array path: the
        copies go back to their own games first (`ArrayPath.push`), and back again later.
        """
        if method_name == "set_policies" and self._array is not None:
            self._array.push()
            self._array = None
        out = super().env_method(method_name, *method_args, indices=indices, **method_kwargs)
        if method_name == "set_policies" and self.array:
            self._array = array_path(self.envs, self.exact)
            if self._array is not None:
                for i in range(self.num_envs):
                    self._array.pulled(i)
        return out

    def reset(self) -> Any:
        """Reset every view (SB3's seeds and options), then let the array game read them."""
        obs = super().reset()
        for i in range(self.num_envs):
            self.view_reset(i)
        return obs

    def view_reset(self, i: int) -> None:
        """Hear that view `i` was reset on its own (the array path then reads its game)."""
        if self._array is not None:
            self._array.pulled(i)

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict]]:
        """Step every view with its action; autoreset finished views as `DummyVecEnv` does."""
        views = self.envs
        if len(views) == 1:  # one view: its own step is the lockstep of one
            return self._results([views[0].step(self.actions[0])])
        if self._array is not None:
            return self._results(self._array.step(self.actions))
        tallies: list[Any] = [None] * len(views)
        for idx in lockstep.groups(self._games, range(len(views))):
            for i, move in zip(idx, self._play(idx, self.actions), strict=True):
                tallies[i] = views[i]._decided(move)
        waiting = self._waiting(range(len(views)))
        while waiting:
            for idx in lockstep.groups(self._games, waiting):
                for i, move in zip(idx, self._play(idx), strict=True):
                    views[i]._add(move, tallies[i])
            waiting = self._waiting(waiting)
        return self._results([view._finish(t) for view, t in zip(views, tallies, strict=True)])

    def _results(self, steps: list[tuple]) -> tuple[Any, np.ndarray, np.ndarray, list[dict]]:
        """`DummyVecEnv`'s return of the views' `steps` (finished views autoreset)."""
        infos, rewards, dones = self.buf_infos, [], []
        buf = self.buf_obs[None] if self._box else None  # type: ignore[index]  # SB3: Box at None
        for i, (view, (obs, reward, terminated, truncated, info)) in enumerate(
            zip(self.envs, steps, strict=True)
        ):
            done = terminated or truncated
            info["TimeLimit.truncated"] = truncated and not terminated
            if done:
                info["terminal_observation"] = obs
                obs, self.reset_infos[i] = view.reset()
                self.view_reset(i)
            infos[i] = info
            if buf is not None:
                buf[i] = obs
            else:
                self._save_obs(i, obs)
            rewards.append(reward)
            dones.append(done)
        self.rewards[:] = self.buf_rews[:] = rewards
        self.buf_dones[:] = dones
        # each info is a fresh dict of this step (`_finish`), so no deep copy is needed
        return self._obs_from_buf(), np.copy(self.buf_rews), np.copy(self.buf_dones), list(infos)

    def _waiting(self, idx: Any) -> list[int]:
        """The views of `idx` with moves to play before their learner decides."""
        views = self.envs
        return [i for i in idx if views[i]._waiting()]

    def _play(self, idx: list[int], learner: Any = None) -> list[Move]:
        """The next move of views `idx` (one `lockstep.groups` group); `learner`: all N actions.

        Each embedded agent's policies are asked once for the group (`act_batch`).
        """
        views, games = self.envs, self._games
        actions: dict[str, Any] = {}
        for agent, _ in views[idx[0]]._players_now():  # the group's views share their movers
            actions[agent] = act_batch(
                [views[i].policies[agent] for i in idx],
                [games[i].observe(agent) for i in idx],
                self.exact,
            )
        if learner is not None:
            actions[self.agent] = learner if len(idx) == len(views) else [learner[i] for i in idx]
        play = lockstep.play_all if self._alike else lockstep.play_each
        return play([games[i] for i in idx], actions)

    def _obs_from_buf(self) -> Any:
        """The observation buffer's copy (one array copy for a Box; SB3 deep-copies a dict)."""
        if self._box:
            return self.buf_obs[None].copy()  # type: ignore[index]  # SB3 keys a Box by None
        return super()._obs_from_buf()


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
            self.vector.view_reset(i)
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
