"""Task bases: the simulator tasks a game is built on, behind one small interface.

A `TaskBase` hides whether the protagonists live in a single Gymnasium env, a MaMuJoCo
ParallelEnv or a robosuite env. The game sees a dict of protagonist observations, one team
reward, one team cost, and (for environment disruptors) a `MujocoSim` handle on the model.
"""

from __future__ import annotations

import abc
import logging
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import numpy as np

from advgame.core.mujoco_timers import quiet_timers
from advgame.errors import ConfigError, UnknownNameError, did_you_mean

__all__ = ["ArrayResult", "GymTask", "MujocoSim", "StepResult", "TaskBase"]

log = logging.getLogger(__name__)

StepResult = tuple[dict[str, Any], float, float, bool, bool, dict[str, Any]]
"""(observations, team reward, team cost, terminated, truncated, info) of one task step."""


class ArrayResult(NamedTuple):
    """One step of N copies of a task base (`TaskBase.step_arrays`), row ``i`` for copy ``i``."""

    observations: dict[str, np.ndarray]
    """Each protagonist's observations ``[N, ...]``."""
    reward: np.ndarray
    """Team rewards ``[N]`` (float64)."""
    cost: np.ndarray
    """Team costs ``[N]`` (float64)."""
    terminated: np.ndarray
    """``[N]`` bool."""
    truncated: np.ndarray
    """``[N]`` bool (the task's own limit; the array game adds the time limit)."""
    info: dict[str, np.ndarray]
    """The task's info terms every copy has, ``[N, ...]`` each."""


class MujocoSim:
    """A handle on a MuJoCo model and data that environment disruptors edit.

    It snapshots nothing itself: disruptors record the nominal values they touch. It knows how
    to recompile the model from its XML through `mujoco.MjSpec` (for shape changes such as body
    lengths) and to swap the recompiled model in, keeping the simulation state.

    Args:
        owner: the object whose ``model``/``data`` attributes are the live simulation
            (a Gymnasium ``MujocoEnv``).
        xml_path: the model file, used to build an `MjSpec` on first use.

    """

    def __init__(self, owner: Any, xml_path: str | None) -> None:
        self._owner = owner
        self._xml_path = xml_path
        self._spec: Any = None
        self._nominal_model = owner.model
        self._swapped = False
        self.epoch = 0
        """Incremented whenever a new model object is swapped in; edits made to the old one are gone."""

    @property
    def model(self) -> Any:
        """The live `mujoco.MjModel`."""
        return self._owner.model

    @property
    def data(self) -> Any:
        """The live `mujoco.MjData`."""
        return self._owner.data

    @property
    def spec(self) -> Any:
        """An `mujoco.MjSpec` of the nominal model, parsed on first use."""
        if self._spec is None:
            import mujoco

            if self._xml_path is None:
                raise ConfigError(
                    "This task base has no model file; shape changes are unavailable."
                )
            spec = mujoco.MjSpec.from_file(self._xml_path)
            spec.compile()  # recompile() keeps qpos/qvel only once the spec has been compiled
            self._spec = spec
        return self._spec

    def body_id(self, name: str) -> int:
        """The id of body `name`, with a helpful error for a typo."""
        return self._id("body", name, self.model.nbody)

    def geom_id(self, name: str) -> int:
        """The id of geom `name`, with a helpful error for a typo."""
        return self._id("geom", name, self.model.ngeom)

    def joint_id(self, name: str) -> int:
        """The id of joint `name`, with a helpful error for a typo."""
        return self._id("joint", name, self.model.njnt)

    def actuator_id(self, name: str) -> int:
        """The id of actuator `name`, with a helpful error for a typo."""
        return self._id("actuator", name, self.model.nu)

    def names(self, kind: str) -> list[str]:
        """All non-empty names of `kind` (``body``, ``geom``, ``joint``, ``actuator``)."""
        count = {"body": "nbody", "geom": "ngeom", "joint": "njnt", "actuator": "nu"}[kind]
        getter = getattr(self.model, kind)
        return [getter(i).name for i in range(getattr(self.model, count)) if getter(i).name]

    def _id(self, kind: str, name: str, count: int) -> int:
        import mujoco

        obj = {
            "body": mujoco.mjtObj.mjOBJ_BODY,
            "geom": mujoco.mjtObj.mjOBJ_GEOM,
            "joint": mujoco.mjtObj.mjOBJ_JOINT,
            "actuator": mujoco.mjtObj.mjOBJ_ACTUATOR,
        }[kind]
        idx = mujoco.mj_name2id(self.model, obj, name)
        if idx < 0:
            names = self.names(kind)
            raise UnknownNameError(
                f"No {kind} named {name!r} in this model.{did_you_mean(name, names)} "
                f"Known {kind} names: {names}."
            )
        return int(idx)

    def body_moved(self, name: str, delta: Any) -> None:
        """Hear that body `name` moved by `delta` (world frame); a no-op by default.

        A task base can keep caches that depend on the body in step (robosuite's table offset).
        """

    def recompile(self) -> None:
        """Compile `spec` (after edits) and swap it in, keeping qpos/qvel/act/time."""
        model, data = self.spec.recompile(self.model, self.data)
        self._install(model, data)
        self._swapped = True

    def restore_model(self) -> None:
        """Swap the nominal compiled model back in if a recompiled one is live."""
        if not self._swapped:
            return
        import mujoco

        data = mujoco.MjData(self._nominal_model)
        self._install(self._nominal_model, data)
        self._swapped = False

    def _install(self, model: Any, data: Any) -> None:
        self._owner.model = model
        self._owner.data = data
        self.epoch += 1
        quiet_timers()  # a new MjData sets MuJoCo's timers again
        renderer = getattr(self._owner, "mujoco_renderer", None)
        if renderer is not None:  # viewers hold the old model; rebuild them lazily
            renderer.model, renderer.data = model, data
            if hasattr(renderer, "close"):
                renderer.close()
            renderer._viewers, renderer.viewer = {}, None


class TaskBase(abc.ABC):
    """The simulator task under a game: protagonists, their spaces, one team payoff.

    Subclasses wrap one kind of simulator. Observations are dicts keyed by protagonist id;
    reward and cost are team scalars (every protagonist shares them, as in MaMuJoCo).
    """

    protagonists: tuple[str, ...]
    """Protagonist agent ids, in a fixed order."""
    observation_spaces: dict[str, gym.spaces.Space]
    """Each protagonist's observation space."""
    action_spaces: dict[str, gym.spaces.Space]
    """Each protagonist's action space."""
    state_space: gym.spaces.Space
    """The space of the true global state that adversaries observe."""
    max_episode_steps: int | None = None
    """Truncation horizon, if the task has one."""
    has_cost: bool = False
    """Whether the task computes a safety cost (a cost weight needs one)."""
    goal_reward: Callable[[Any, Any, Any], Any] | None = None
    """Goal-conditioned tasks with Box goals: their reward ``(achieved_goal, desired_goal,
    info)``, vectorised, for hindsight relabelling; None for every other task. A protagonist's
    single-agent view exposes it as ``compute_reward``."""

    @abc.abstractmethod
    def reset(self, seed: int | None) -> tuple[dict[str, Any], dict[str, Any]]:
        """Start an episode; return protagonist observations and the task's info."""

    @abc.abstractmethod
    def step(self, actions: Mapping[str, Any]) -> StepResult:
        """Advance one step with each protagonist's (already disrupted) action."""

    @classmethod
    def step_many(
        cls, tasks: Sequence[TaskBase], actions: Sequence[Mapping[str, Any]]
    ) -> list[StepResult]:
        """``[task.step(acts) for task, acts in zip(tasks, actions)]``: alike games' tasks.

        `advgame.core.lockstep` calls it with the tasks of N alike games (all of this class)
        moving together; a task base that can step its simulators as one batch overrides it
        (`advgame.scenarios.mujoco_batch.BatchedGymTask`) and must return what the loop
        would, bit for bit.
        """
        return [t.step(a) for t, a in zip(tasks, actions, strict=True)]

    batched: ClassVar[bool] = False
    """Whether `step_arrays` steps the copies' simulators as one batch (else one by one)."""

    @classmethod
    def step_arrays(
        cls,
        tasks: Sequence[TaskBase],
        actions: Mapping[str, np.ndarray],
        threads: int | None = None,
    ) -> ArrayResult:
        """Step N alike tasks, ``actions[p][i]`` for copy ``i``, and stack what they return.

        The array game (`advgame.core.array_game.ArrayGame`) calls it. This default steps the
        copies one by one (`step_many`); a task base whose simulators batch overrides it and
        sets `batched`, returning the same arrays bit for bit. `threads` caps the simulator
        threads of a batched step.
        """
        n = len(tasks)
        results = cls.step_many(tasks, [{p: a[i] for p, a in actions.items()} for i in range(n)])
        obs = {p: np.stack([r[0][p] for r in results]) for p in results[0][0]}
        info: dict[str, np.ndarray] = {}
        for key in results[0][5]:
            if all(key in r[5] for r in results):
                try:
                    info[key] = np.asarray([r[5][key] for r in results])
                except ValueError:  # ragged: not an array term
                    continue
        return ArrayResult(
            obs,
            np.array([r[1] for r in results], np.float64),
            np.array([r[2] for r in results], np.float64),
            np.array([r[3] for r in results], np.bool_),
            np.array([r[4] for r in results], np.bool_),
            info,
        )

    @abc.abstractmethod
    def state(self, observations: Mapping[str, Any]) -> Any:
        """The true global state adversaries observe, given the current true observations."""

    def observe(self) -> dict[str, Any]:
        """The protagonists' observations of the current simulator state, after an edit.

        Reset-time (workspace) disruptors move things after the task's reset; the game then asks
        for fresh observations. Tasks that cannot re-observe raise.
        """
        raise ConfigError(
            f"{type(self).__name__} cannot re-observe its simulator; workspace disruptors need a "
            "task base that can (robosuite tasks)."
        )

    @property
    def sim(self) -> MujocoSim:
        """The MuJoCo handle for environment disruptors; tasks without one raise."""
        raise ConfigError(
            f"{type(self).__name__} has no MuJoCo model; dynamics and force disruptors need one."
        )

    def render(self) -> Any:
        """Render the task (as its `render_mode` says)."""
        return None

    def close(self) -> None:  # noqa: B027 - an optional hook, no-op by default
        """Release simulator resources."""


class GymTask(TaskBase):
    """A single-agent Gymnasium env as a task base with one protagonist, ``"protagonist"``.

    Args:
        env_id: a registered Gymnasium id, e.g. ``"HalfCheetah-v5"``.
        cost_key: the `info` key holding a safety cost, if the task has one.
        **kwargs: passed to `gymnasium.make` (``render_mode``, ``max_episode_steps``, ...).

    """

    AGENT = "protagonist"

    def __init__(self, env_id: str, cost_key: str | None = None, **kwargs: Any) -> None:
        kwargs.setdefault("disable_env_checker", True)
        self.env = gym.make(env_id, **kwargs)
        self.env_id = env_id
        self.cost_key = cost_key
        self.has_cost = self.has_cost or cost_key is not None
        self.protagonists = (self.AGENT,)
        self.observation_spaces = {self.AGENT: self.env.observation_space}
        self.action_spaces = {self.AGENT: self.env.action_space}
        self.state_space = self.env.observation_space
        self.max_episode_steps = self.env.spec.max_episode_steps if self.env.spec else None
        self._sim: MujocoSim | None = None
        self._inner = self.env.unwrapped if self._plain_wrappers(self.env) else self.env
        self._steps = 0

    @staticmethod
    def _plain_wrappers(env: gym.Env) -> bool:
        """Whether every wrapper is one the game replaces (time limit, order, env checker)."""
        from gymnasium.wrappers import OrderEnforcing, PassiveEnvChecker, TimeLimit

        while isinstance(env, gym.Wrapper):
            if not isinstance(env, (TimeLimit, OrderEnforcing, PassiveEnvChecker)):
                return False
            env = env.env
        return True

    def reset(self, seed: int | None) -> tuple[dict[str, Any], dict[str, Any]]:
        """Reset the Gymnasium env with `seed`."""
        obs, info = self.env.reset(seed=seed)
        self._steps = 0
        return {self.AGENT: obs}, info

    def step(self, actions: Mapping[str, Any]) -> StepResult:
        """Step the Gymnasium env with the protagonist's action.

        The game enforces call order and the time limit itself, so the unwrapped env is stepped
        directly (skipping the `TimeLimit`/`OrderEnforcing` wrappers' per-step overhead).
        """
        return self._result(*self._inner.step(actions[self.AGENT]))

    def _result(
        self, obs: Any, reward: Any, terminated: Any, truncated: Any, info: dict[str, Any]
    ) -> StepResult:
        """The task's result of one env step: the time limit counted, the cost read from info."""
        self._steps += 1
        if self.max_episode_steps is not None and self._steps >= self.max_episode_steps:
            truncated = True
        cost = float(info.get(self.cost_key, 0.0)) if self.cost_key else 0.0
        return {self.AGENT: obs}, float(reward), cost, bool(terminated), bool(truncated), info

    def state(self, observations: Mapping[str, Any]) -> Any:
        """The protagonist's true observation is the state."""
        return observations[self.AGENT]

    def observe(self) -> dict[str, Any]:
        """Re-observe a Gymnasium MuJoCo env after a simulator edit (its ``_get_obs``)."""
        inner: Any = self.env.unwrapped
        get_obs = getattr(inner, "_get_obs", None)
        if get_obs is None or not hasattr(inner, "data"):
            return super().observe()
        import mujoco

        mujoco.mj_forward(inner.model, inner.data)
        return {self.AGENT: get_obs()}

    @property
    def sim(self) -> MujocoSim:
        """The MuJoCo handle (MuJoCo tasks only)."""
        if self._sim is None:
            inner = self.env.unwrapped
            if not hasattr(inner, "model") or not hasattr(inner, "data"):
                return super().sim
            self._sim = MujocoSim(inner, getattr(inner, "fullpath", None))
        return self._sim

    def render(self) -> Any:
        """Render through the Gymnasium env."""
        return self.env.render()

    def close(self) -> None:
        """Close the Gymnasium env."""
        self.env.close()
