"""A batched task base: N copies of a Gymnasium MuJoCo v5 task stepped together.

`BatchedMujocoEnv` is a Gymnasium `VectorEnv` of N copies of one of the eleven MuJoCo v5 tasks.
Each copy is the env ``gymnasium.make(env_id, **kwargs)`` builds (its model, its `MjData`, its
reset and reset noise), but a step moves all of them at once: the controls of every copy are set
and MuJoCo steps the copies on a pool of threads (`advgame.core.physics.ThreadedStepper`), then
observations, rewards, terminations, truncations and every info term come out of NumPy over
``[N, ...]`` (`advgame.scenarios.mujoco_formulas`) instead of N Python ``step`` calls, N wrapper
stacks and N info dicts. Autoreset is Gymnasium's ``NEXT_STEP`` mode and infos are merged as
`SyncVectorEnv` merges them, so it is a drop-in for
``SyncVectorEnv([lambda: gymnasium.make(env_id)] * N)``: same seeds, same actions, the same
arrays bit for bit (``tests/test_mujoco_batch.py`` plays whole episodes of every task, resets,
reset noise and healthy-range terminations included).

Example:
    >>> import numpy as np
    >>> from advgame.scenarios.mujoco_batch import BatchedMujocoEnv
    >>> envs = BatchedMujocoEnv("HalfCheetah-v5", num_envs=4, threads=1)
    >>> obs, info = envs.reset(seed=0)
    >>> obs.shape
    (4, 17)
    >>> obs, reward, terminated, truncated, info = envs.step(np.zeros((4, 6)))
    >>> reward.shape, sorted(info)[:2]
    ((4,), ['_reward_ctrl', '_reward_forward'])
    >>> envs.close()

"""

from __future__ import annotations

import operator
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from advgame.core.physics import ThreadedStepper, shared_stepper
from advgame.core.task import ArrayResult, GymTask, StepResult
from advgame.errors import ConfigError, UnknownNameError, did_you_mean
from advgame.scenarios.mujoco_formulas import FORMULAS, Formula, Outcome, Stacked
from advgame.scenarios.mujoco_lean import lean_step

__all__ = ["TASKS", "BatchedGymTask", "BatchedMujocoEnv", "batched_step", "step_envs"]

TASKS = tuple(FORMULAS)
"""The task ids a `BatchedMujocoEnv` can batch."""


def step_envs(
    envs: Any, formula: Formula, actions: np.ndarray, stepper: ThreadedStepper
) -> Outcome:
    """Step unwrapped Gymnasium MuJoCo envs of one task once each, as their ``step`` would.

    Args:
        envs: the envs (same task and keyword arguments), in row order.
        formula: the task's `Formula`.
        actions: ``[len(envs), nu]``, one action per env.
        stepper: the threads that run MuJoCo.

    Returns:
        observations, rewards and terminations over the rows, and the info arrays.

    """
    env = envs[0]
    # a `before` that reads only fields the stepping loop can read for it runs on them after
    # the step; any other reads every env first
    early = None if formula.reads_before else formula.before(Stacked(envs), env)
    got = stepper.step(
        envs,
        actions,
        env.frame_skip,
        formula.contact_forces,
        before=formula.reads_before,
        after=formula.reads_after,
    )
    before = formula.before(Stacked(envs, got.before), env) if formula.reads_before else early
    if type(env).dt is MujocoEnv.dt:  # Gymnasium's own property (one task: one env type)
        dt = got.timestep * env.frame_skip  # its product, made for every row at once
    else:
        dt = np.fromiter(map(_DT, envs), np.float64, len(envs))
    return formula.after(Stacked(envs, got.after), env, before, actions, dt)


def batched_step(
    tasks: Any, actions: np.ndarray, threads: int | None = None
) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, dict[str, Any]] | None:
    """Step the unwrapped envs of `GymTask` copies of one MuJoCo v5 task as one batch.

    Returns ``({"protagonist": obs}, rewards, terminations, infos)`` over ``[N, ...]``, or
    None when the copies cannot batch (another task or keywords, extra wrappers, rendering, a
    wrong action shape): the caller then steps them one by one.
    """
    t0 = tasks[0]
    try:  # every key made once per task: compared in C, not one Python call a copy
        keys = set(map(_KEY, tasks))
    except AttributeError:
        keys = {_array_key(t) for t in tasks}
    key = _array_key(t0)
    if len(keys) != 1 or key[1] not in FORMULAS:
        return None
    if actions.shape != (len(tasks), t0._inner.model.nu):
        return None
    envs = list(map(_INNER, tasks))
    env_id = key[1]
    obs, reward, terminated, info = step_envs(
        envs, FORMULAS[env_id], actions, shared_stepper(threads)
    )
    return {GymTask.AGENT: obs}, reward, terminated, info


_DT = operator.attrgetter("dt")
_KEY = operator.attrgetter("_array_key")
_INNER = operator.attrgetter("_inner")


def _array_key(task: Any) -> tuple[Any, ...]:
    """What copies must share to step as one batch (task, keywords; ``None``: cannot batch).

    Made once per task (its env does not change); a task with wrappers the game does not
    replace, or one that renders, gets a key of its own.
    """
    key: tuple[Any, ...] | None = task.__dict__.get("_array_key")
    if key is None:
        inner, spec = task.env.unwrapped, task.env.spec
        plain = task._inner is inner and inner.render_mode is None
        env_id = inner.spec.id if inner.spec else None
        kwargs = repr(spec.kwargs if spec else None)
        key = (type(task), env_id, kwargs) if plain else (id(task), None)
        task._array_key = key
    return key


class BatchedMujocoEnv(VectorEnv):
    """N copies of a Gymnasium MuJoCo v5 task stepped as one batch (see the module docstring).

    Args:
        env_id: one of `TASKS` (``"Hopper-v5"``, ...).
        num_envs: copies in the batch.
        threads: simulator threads (``None``: the cores this process may use; 1 steps on the
            calling thread).
        max_episode_steps: the time limit (``None``: the registered one, 1000 for most tasks).
        **kwargs: passed to ``gymnasium.make`` for every copy (``ctrl_cost_weight=...``).

    Attributes:
        envs: the N unwrapped Gymnasium envs; their ``model``/``data`` are the live simulations
            (environment disruptors edit them as they edit a single env's).

    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}  # noqa: RUF012 - as VectorEnv

    def __init__(
        self,
        env_id: str,
        num_envs: int,
        *,
        threads: int | None = None,
        max_episode_steps: int | None = None,
        **kwargs: Any,
    ) -> None:
        if env_id not in FORMULAS:
            raise UnknownNameError(
                f"No batched task {env_id!r}.{did_you_mean(env_id, TASKS)} "
                f"Batched tasks: {', '.join(TASKS)}."
            )
        if not isinstance(num_envs, int) or isinstance(num_envs, bool) or num_envs < 1:
            raise ConfigError(f"num_envs must be a positive integer; got {num_envs!r}.")
        spec = gym.spec(env_id)
        limit = spec.max_episode_steps if max_episode_steps is None else max_episode_steps
        if limit is not None and (not isinstance(limit, int) or limit < 1):
            raise ConfigError(f"max_episode_steps must be a positive integer; got {limit!r}.")
        self.env_id = env_id
        self.num_envs = num_envs
        self.max_episode_steps: int | None = limit
        """Steps after which an episode is truncated (``None``: never)."""
        self.envs: list[Any] = [gym.make(env_id, **kwargs).unwrapped for _ in range(num_envs)]
        self._formula = FORMULAS[env_id]
        self._stepper = ThreadedStepper(threads)
        first: Any = self.envs[0]
        self.single_observation_space = first.observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(first.observation_space, num_envs)
        self.action_space = batch_space(first.action_space, num_envs)
        self.spec = spec
        self.render_mode = None
        self._nu = int(first.model.nu)
        self._obs = np.zeros((num_envs, *first.observation_space.shape), np.float64)
        self._rewards = np.zeros(num_envs, np.float64)
        self._terminations = np.zeros(num_envs, np.bool_)
        self._truncations = np.zeros(num_envs, np.bool_)
        self._autoreset = np.zeros(num_envs, np.bool_)
        self._elapsed = np.zeros(num_envs, np.int64)
        self._was_reset = False

    @property
    def threads(self) -> int:
        """The most simulator threads a step uses."""
        return min(self._stepper.threads, self.num_envs)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every copy (or those in ``options["reset_mask"]``), as `SyncVectorEnv` does.

        Args:
            seed: ``None`` (fresh entropy), an int ``s`` (copy ``i`` gets ``s + i``) or one
                seed per copy.
            options: passed to each copy's reset; ``reset_mask`` (a bool array) resets only
                the copies marked.

        """
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, int | np.integer):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ConfigError(
                    f"reset got {len(seeds)} seeds for {self.num_envs} envs; pass one per "
                    "env, an int, or None."
                )
        options = dict(options) if options else None
        mask = np.ones(self.num_envs, bool)
        if options is not None and "reset_mask" in options:
            mask = np.asarray(options.pop("reset_mask"))
            if mask.shape != (self.num_envs,) or mask.dtype != np.bool_ or not mask.any():
                raise ConfigError(
                    f"options['reset_mask'] must be a bool array of shape ({self.num_envs},) "
                    f"with at least one True; got {mask!r}."
                )
        infos: dict[str, Any] = {}
        for i in np.flatnonzero(mask):
            infos = self._reset_one(int(i), infos, seed=seeds[i], options=options)
        self._terminations[mask] = False
        self._truncations[mask] = False
        self._autoreset[mask] = False
        self._was_reset = True
        return self._obs.copy(), infos

    def _reset_one(self, i: int, infos: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        obs, info = self.envs[i].reset(**kwargs)
        self._obs[i] = obs
        self._elapsed[i] = 0
        return self._add_info(infos, info, i)

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every copy with its row of `actions` (copies whose episode ended reset instead).

        Returns:
            observations ``[N, obs]``, rewards ``[N]``, terminations ``[N]``, truncations
            ``[N]`` and the merged infos (each key with its ``_key`` mask), as `SyncVectorEnv`.

        """
        if not self._was_reset:
            raise gym.error.ResetNeeded("Call reset() before step() on a BatchedMujocoEnv.")
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs, self._nu):
            raise ConfigError(
                f"{self.env_id} takes actions of shape ({self.num_envs}, {self._nu}) for "
                f"{self.num_envs} envs; got {actions.shape}."
            )
        infos: dict[str, Any] = {}
        resetting = self._autoreset.copy()
        for i in np.flatnonzero(resetting):
            infos = self._reset_one(int(i), infos)
            self._rewards[i] = 0.0
            self._terminations[i] = False
            self._truncations[i] = False
        rows = np.flatnonzero(~resetting)
        if rows.size:
            self._step_rows(rows, actions[rows], infos)
        self._autoreset = self._terminations | self._truncations
        return (
            self._obs.copy(),
            self._rewards.copy(),
            self._terminations.copy(),
            self._truncations.copy(),
            infos,
        )

    def _step_rows(self, rows: np.ndarray, actions: np.ndarray, infos: dict[str, Any]) -> None:
        envs = [self.envs[i] for i in rows]
        obs, reward, terminated, info = step_envs(envs, self._formula, actions, self._stepper)
        self._obs[rows] = obs
        self._rewards[rows] = reward
        self._terminations[rows] = terminated
        self._elapsed[rows] += 1
        if self.max_episode_steps is not None:
            self._truncations[rows] = self._elapsed[rows] >= self.max_episode_steps
        else:
            self._truncations[rows] = False
        for key, values in info.items():
            values = np.asarray(values)
            if key not in infos:
                infos[key] = np.zeros((self.num_envs, *values.shape[1:]), values.dtype)
                infos[f"_{key}"] = np.zeros(self.num_envs, np.bool_)
            infos[key][rows] = values
            infos[f"_{key}"][rows] = True

    def close_extras(self, **kwargs: Any) -> None:
        """Stop the simulator threads and close the copies."""
        self._stepper.close()
        for env in self.envs:
            env.close()


class BatchedGymTask(GymTask):
    """A Gymnasium MuJoCo v5 task base whose alike games step their simulators as one batch.

    A single game steps it exactly as `GymTask`, through the task's lean step where it has one
    (`advgame.scenarios.mujoco_lean`: ``env.step``'s results with less Python). N alike games
    moving together (`advgame.core.lockstep`, under `advgame.core.vector.VectorView` and
    batched evaluation) call `step_many`, which steps all N simulators on the process's shared
    simulator threads (`advgame.core.physics.shared_stepper`) and computes observations, rewards
    and infos over ``[N, ...]`` (`step_envs`): the same results, bit for bit, as N ``step``
    calls.

    Args:
        env_id: one of `TASKS`.
        **kwargs: as `GymTask`.

    """

    def __init__(self, env_id: str, cost_key: str | None = None, **kwargs: Any) -> None:
        super().__init__(env_id, cost_key=cost_key, **kwargs)
        self._batch_key = (env_id, cost_key, repr(sorted(kwargs.items())))
        plain = self._inner is self.env.unwrapped
        self._lean = lean_step(self._inner) if plain else None

    def step(self, actions: Any) -> StepResult:
        """`GymTask.step`, through the task's lean step where it has one (`mujoco_lean`)."""
        if self._lean is None:
            return super().step(actions)
        return self._result(*self._lean(actions[self.AGENT]))

    @classmethod
    def step_many(cls, tasks: Any, actions: Any) -> list[StepResult]:
        """Step every task with its protagonist action, batched where the tasks allow it.

        Tasks batch together when they share a task id and keyword arguments, carry only the
        wrappers a game replaces, do not render, and their actions share a dtype and shape;
        otherwise each task steps on its own (`GymTask.step`).
        """
        t0 = tasks[0]
        same = all(
            isinstance(t, BatchedGymTask)
            and t._batch_key == t0._batch_key
            and t._inner is t.env.unwrapped
            and t._inner.render_mode is None  # a rendering env draws inside its own step
            for t in tasks
        )
        arrays = [np.asarray(a[cls.AGENT]) for a in actions]
        kinds = {(a.dtype, a.shape) for a in arrays}
        if not same or len(kinds) != 1 or arrays[0].shape != (t0._inner.model.nu,):
            # step one by one (a wrong shape then raises the single env's own error)
            return super().step_many(tasks, actions)
        envs = [t._inner for t in tasks]
        obs, reward, terminated, info = step_envs(
            envs, FORMULAS[t0.env_id], np.stack(arrays), shared_stepper()
        )
        return [
            t._result(obs[i], reward[i], terminated[i], False, {k: v[i] for k, v in info.items()})
            for i, t in enumerate(tasks)
        ]

    batched = True

    @classmethod
    def step_arrays(cls, tasks: Any, actions: Any, threads: int | None = None) -> ArrayResult:
        """Step N copies as one batch (`batched_step`); one by one where they cannot batch."""
        stepped = batched_step(tasks, np.asarray(actions[cls.AGENT]), threads)
        if stepped is None:
            return super().step_arrays(tasks, actions, threads)
        obs, reward, terminated, info = stepped
        n = len(tasks)
        cost_key = tasks[0].cost_key
        cost = np.asarray(info[cost_key], np.float64) if cost_key in info else np.zeros(n)
        return ArrayResult(obs, reward, cost, terminated, np.zeros(n, np.bool_), info)
