"""robosuite manipulation tasks as task bases: flattened observations, external arms, a sim handle.

`RobosuiteTask` builds a robosuite 1.5 environment with no on-screen renderer, no camera
observations and no off-screen rendering (``camera_obs=True`` turns image observations on) and
``hard_reset=False``, so one compiled model lives for the whole game and dynamics disruptors
edit it through a `MujocoSim` handle (restored exactly on every reset by the game).

**Flattened observations.** robosuite returns a dict of arrays; the protagonist observes their
concatenation in this documented, stable order: ``robot<i>_proprio-state`` for each robot the
protagonist controls (in robot order), then ``object-state``, then (with ``camera_obs``) each
``<camera>_image`` flattened. `RobosuiteTask.observation_keys` maps each key to its index range,
so a disruptor can target one key (``ObservationDisruptor(keys=["object-state"])``).

**External arms.** Robots listed in ``external_robots`` are not the protagonist's: their part
of robosuite's action vector comes from `RobosuiteTask.external_actions` (zeros unless an
`ArmDisruptor` writes it), and the true state adversaries observe appends their proprio-state.
This is how MultiRobustDoor's second arm becomes an adversary agent.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from advgame.core.task import MujocoSim, StepResult, TaskBase
from advgame.errors import ConfigError, UnknownNameError, did_you_mean

__all__ = ["AGENT", "RobosuiteSim", "RobosuiteTask", "flat_keys"]

log = logging.getLogger(__name__)

AGENT = "protagonist"
"""The protagonist id of every robosuite scenario."""


class _Owner:
    """Exposes robosuite's wrapped `MjModel`/`MjData` as the ``model``/``data`` a `MujocoSim` edits."""

    def __init__(self, env: Any) -> None:
        self.env = env

    @property
    def model(self) -> Any:
        """The raw `mujoco.MjModel` under robosuite's `MjSim` wrapper."""
        return self.env.sim.model._model

    @property
    def data(self) -> Any:
        """The raw `mujoco.MjData` under robosuite's `MjSim` wrapper."""
        return self.env.sim.data._data


class RobosuiteSim(MujocoSim):
    """The `MujocoSim` handle of a robosuite env: no model file, so no recompiled shape changes.

    When the ``table`` body moves, robosuite's cached table offsets (its success checks read
    them) follow, and go back when the table does.
    """

    def __init__(self, env: Any) -> None:
        super().__init__(_Owner(env), None)
        self._env = env
        arena = getattr(getattr(env, "model", None), "mujoco_arena", None)
        self._caches = [
            (owner, np.array(owner.table_offset, dtype=np.float64))
            for owner in (env, arena)
            if owner is not None and np.shape(getattr(owner, "table_offset", ())) == (3,)
        ]
        self._table = self.body_id("table") if "table" in self.names("body") else -1
        self._table_pos = self.model.body_pos[self._table].copy() if self._table >= 0 else None

    def body_moved(self, name: str, delta: np.ndarray) -> None:
        """Set robosuite's ``table_offset`` caches to nominal + the table body's displacement.

        Computed from the body's position (not accumulated), so the caches are exactly
        nominal again once the body is.
        """
        if name != "table" or self._table_pos is None:
            return
        shift = self.model.body_pos[self._table] - self._table_pos
        for owner, nominal in self._caches:
            owner.table_offset = nominal + shift


def flat_keys(obs: Mapping[str, Any], keys: Sequence[str]) -> np.ndarray:
    """Concatenate ``obs[k]`` for `keys`, each flattened, as float64."""
    return np.concatenate([np.asarray(obs[k], dtype=np.float64).reshape(-1) for k in keys])


class RobosuiteTask(TaskBase):
    """A robosuite environment as a task base with one protagonist, ``"protagonist"``.

    Args:
        env_name: a robosuite environment (``"Lift"``, ``"TwoArmLift"``, ``"MultiRobustDoor"``...).
        robots: robot model per arm (``"Panda"``, or one per arm for two-arm tasks).
        external_robots: indices of robots the protagonist does not control (adversary arms).
        max_episode_steps: truncation horizon (robosuite's own horizon is disabled).
        camera_obs: add ``agentview`` image observations (needs an off-screen GL context).
        reward_shaping: robosuite's dense rewards (the paper trains with them).
        model_seed: seeds what robosuite draws when it builds the model (e.g. Lift's cube
            size), so every game built with the same arguments has the same model;
            `reset(seed=...)` then seeds placements and initial joint noise.
        **env_kwargs: passed to `robosuite.make` (``env_configuration``, ``control_freq``...).

    """

    def __init__(
        self,
        env_name: str,
        robots: str | Sequence[str] = "Panda",
        external_robots: Sequence[int] = (),
        max_episode_steps: int = 200,
        camera_obs: bool = False,
        reward_shaping: bool = True,
        model_seed: int = 0,
        **env_kwargs: Any,
    ) -> None:
        if int(max_episode_steps) < 1:
            raise ConfigError(f"max_episode_steps must be >= 1, got {max_episode_steps!r}.")
        options = {"seed": int(model_seed), "reward_shaping": reward_shaping, **env_kwargs}
        self.env = _make_env(env_name, robots, camera_obs, options)
        self.env_name = env_name
        self.protagonists = (AGENT,)
        self.max_episode_steps = self._horizon = int(max_episode_steps)
        n = len(self.env.robots)
        self.external = tuple(sorted(int(i) for i in external_robots))
        if any(i < 0 or i >= n for i in self.external) or len(self.external) >= n:
            raise ConfigError(
                f"external_robots must be indices of some (not all) of the {n} robots, "
                f"got {tuple(external_robots)!r}."
            )
        own = [i for i in range(n) if i not in self.external]
        cams = [f"{c}_image" for c in self.env.camera_names] if camera_obs else []
        self.keys = (*(f"robot{i}_proprio-state" for i in own), "object-state", *cams)
        """Observation keys the protagonist sees, in flattening order."""
        self.state_keys = (*self.keys, *(f"robot{i}_proprio-state" for i in self.external))
        """Keys of the true state adversaries observe: the protagonist's, then external arms'."""
        self._slices = self._action_slices()
        self._own = [self._slices[i] for i in own]
        self.external_actions: dict[int, np.ndarray] = {
            i: np.zeros(self._slices[i].stop - self._slices[i].start) for i in self.external
        }
        """Each external robot's command for the next step (set by arm disruptors)."""
        obs = self.env.reset()
        self.observation_keys = self._key_slices(obs, self.keys)
        """Each protagonist observation key -> its slice of the flattened observation."""
        self.observation_spaces = {AGENT: _box(flat_keys(obs, self.keys).size)}
        self.state_space = _box(flat_keys(obs, self.state_keys).size)
        low, high = self.env.action_spec
        idx = np.concatenate([np.arange(s.start, s.stop) for s in self._own])
        self.action_spaces = {
            AGENT: spaces.Box(low[idx].astype(np.float32), high[idx].astype(np.float32))
        }
        self._sim: RobosuiteSim | None = None
        self._steps = 0

    def _action_slices(self) -> dict[int, slice]:
        """Each robot's slice of robosuite's concatenated action vector."""
        out, i = {}, 0
        for r, robot in enumerate(self.env.robots):
            out[r] = slice(i, i + robot.action_dim)
            i += robot.action_dim
        if i != self.env.action_dim:
            raise ConfigError(f"Robot action sizes sum to {i}, not {self.env.action_dim}.")
        return out

    @staticmethod
    def _key_slices(obs: Mapping[str, Any], keys: Sequence[str]) -> dict[str, slice]:
        out, i = {}, 0
        for k in keys:
            n = int(np.asarray(obs[k]).size)
            out[k], i = slice(i, i + n), i + n
        return out

    def reset(self, seed: int | None) -> tuple[dict[str, Any], dict[str, Any]]:
        """Reset robosuite; a seed re-seeds its generator in place (robots and placement share it)."""
        if seed is not None:
            self.env.rng.bit_generator.state = np.random.default_rng(seed).bit_generator.state
        for a in self.external_actions.values():
            a[:] = 0.0
        self._obs = self.env.reset()
        self._steps = 0
        return {AGENT: flat_keys(self._obs, self.keys)}, {}

    def step(self, actions: Mapping[str, Any]) -> StepResult:
        """Step robosuite with the protagonist's action and each external arm's command."""
        full = np.zeros(self.env.action_dim)
        a = np.asarray(actions[AGENT], dtype=np.float64).reshape(-1)
        i = 0
        for s in self._own:
            n = s.stop - s.start
            full[s], i = a[i : i + n], i + n
        for r, command in self.external_actions.items():
            full[self._slices[r]] = command
        self._obs, reward, _, info = self.env.step(full)
        self._steps += 1
        info = {"success": bool(self.env._check_success())}
        truncated = self._steps >= self._horizon
        return {AGENT: flat_keys(self._obs, self.keys)}, float(reward), 0.0, False, truncated, info

    def observe(self) -> dict[str, Any]:
        """Recompute observations after an edit of the simulator (a workspace disturbance)."""
        self.env.sim.forward()
        self._obs = self.env._get_observations(force_update=True)
        return {AGENT: flat_keys(self._obs, self.keys)}

    def state(self, observations: Mapping[str, Any]) -> Any:
        """The protagonist's observation, then every external arm's proprio-state."""
        if not self.external:
            return observations[AGENT]
        extra = flat_keys(self._obs, self.state_keys[len(self.keys) :])
        return np.concatenate([observations[AGENT], extra])

    def robot_slice(self, robot: int) -> slice:
        """Robot `robot`'s slice of robosuite's action vector (with a helpful error)."""
        if robot not in self._slices:
            raise UnknownNameError(f"No robot {robot}; robots: {sorted(self._slices)}.")
        return self._slices[robot]

    @property
    def sim(self) -> RobosuiteSim:
        """The MuJoCo handle on robosuite's model and data."""
        if self._sim is None:
            self._sim = RobosuiteSim(self.env)
        return self._sim

    def close(self) -> None:
        """Close robosuite."""
        self.env.close()


def _box(n: int) -> spaces.Box:
    return spaces.Box(-np.inf, np.inf, shape=(n,), dtype=np.float64)


def _make_env(
    env_name: str,
    robots: str | Sequence[str],
    camera_obs: bool,
    kwargs: dict[str, Any],
) -> Any:
    import robosuite

    import advgame.scenarios.robosuite_causal_envs  # registers LiftCausal and DoorCausal
    import advgame.scenarios.robosuite_envs  # noqa: F401 - registers MultiRobustDoor with robosuite

    _check_name("robosuite environment", env_name, robosuite.ALL_ENVIRONMENTS)
    for robot in [robots] if isinstance(robots, str) else robots:
        _check_name("robosuite robot", robot, robosuite.ALL_ROBOTS)
    options: dict[str, Any] = {
        "has_renderer": False,
        "has_offscreen_renderer": camera_obs,
        "use_camera_obs": camera_obs,
        "hard_reset": False,
        "ignore_done": True,
        "horizon": 10**9,
        **kwargs,
    }
    env = robosuite.make(env_name, robots=robots, **options)
    from advgame.scenarios.robosuite_lean import lean_robots

    lean_robots(env)  # the robots' action size kept, not rebuilt three times a substep
    return env


def _check_name(what: str, name: str, known: Any) -> None:
    """Raise a "did you mean" error for a name robosuite does not know."""
    names = sorted(known)
    if name not in names:
        raise UnknownNameError(f"No {what} {name!r}.{did_you_mean(name, names)} Known: {names}.")
