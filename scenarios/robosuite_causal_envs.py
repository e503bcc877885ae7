"""robosuite environments of the paper's causal tasks: LiftCausal and DoorCausal.

Built after Robust Gymnasium's ``robust_gymnasium/envs/robosuite/environments/causal/
lift_causal.py`` and ``door_causal.py`` (scene, observations and rewards), with one change:
the two correlated features are not drawn here but set by a `WorkspaceDisruptor` at reset
(`advgame.scenarios.robosuite_causal`), so the environment alone is the *undisturbed* scene:
the cube in a 5 cm band around the table's centre line with a colour half way between red and
green, the door facing -pi/2 with its handle half way between the paper's two heights.
Defining the classes registers them with robosuite's in-process registry.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from robosuite.environments.manipulation.door import Door
from robosuite.environments.manipulation.lift import Lift
from robosuite.environments.manipulation.manipulation_env import ManipulationEnv
from robosuite.models.arenas import TableArena
from robosuite.models.objects import BoxObject
from robosuite.models.tasks import ManipulationTask
from robosuite.utils.mjcf_utils import array_to_string, find_elements
from robosuite.utils.observables import Observable, sensor
from robosuite.utils.placement_samplers import UniformRandomSampler

from advgame.scenarios.robosuite_causal import (
    CUBE_NOMINAL_RGBA,
    DOOR_HANDLE,
    DOOR_JITTER,
    DOOR_TABLE_OFFSET,
    LIFT_BAND,
)

__all__ = ["DoorCausal", "LiftCausal"]


class LiftCausal(Lift):
    """Lift a 4 cm cube whose colour (observed, ``cube_color``) may go with its side of the table.

    As the paper's LiftCausal: the cube is a fixed 2 cm half-size box with no texture (its
    colour is its ``rgba``), placed with a fixed yaw of pi; the protagonist's ``object-state``
    ends with the cube's RGB; the reward is 1 once the cube is 4 cm above the table, else (shaped)
    reaching ``1 - tanh(10 d)`` plus 1 while grasping, times ``reward_scale``.
    """

    placement_initializer: Any
    """Where the cube is drawn (robosuite's sampler; ours unless one is passed)."""

    def _load_model(self) -> None:
        """The table, the robot, and the plain cube on the centre-line placement sampler."""
        ManipulationEnv._load_model(self)
        robot = self.robots[0].robot_model
        robot.set_base_xpos(robot.base_xpos_offset["table"](self.table_full_size[0]))
        arena = TableArena(
            table_full_size=self.table_full_size,
            table_friction=self.table_friction,
            table_offset=self.table_offset,
        )
        arena.set_origin([0, 0, 0])
        self.cube = BoxObject(
            name="cube", size=[0.02, 0.02, 0.02], rgba=list(CUBE_NOMINAL_RGBA), material=None
        )
        if self.placement_initializer is None:
            x, y = LIFT_BAND
            self.placement_initializer = UniformRandomSampler(
                name="ObjectSampler",
                x_range=[-x, x],
                y_range=[-y, y],
                rotation=(np.pi, np.pi + 0.001),
                ensure_object_boundary_in_range=False,
                reference_pos=self.table_offset,
                z_offset=0.01,
                rng=self.rng,
            )
        self.placement_initializer.reset()
        self.placement_initializer.add_objects(self.cube)
        self.model = ManipulationTask(
            mujoco_arena=arena, mujoco_robots=[robot], mujoco_objects=self.cube
        )

    def _setup_observables(self) -> Any:
        """Lift's observables plus ``cube_color``: the cube's RGB, from the live model."""
        observables = super()._setup_observables()
        if self.use_object_obs:
            geom = self.sim.model.geom_name2id("cube_g0_vis")

            @sensor(modality="object")
            def cube_color(obs_cache: Any) -> np.ndarray:
                return np.array(self.sim.model.geom_rgba[geom, :3])

            observables["cube_color"] = Observable(
                name="cube_color", sensor=cube_color, sampling_rate=self.control_freq
            )
        return observables

    def reward(self, action: Any = None) -> float:
        """The paper's LiftCausal reward (see the class docstring)."""
        if self._check_success():
            reward = 1.0
        elif self.reward_shaping:
            gripper = self.robots[0].gripper
            dist = self._gripper_to_target(
                gripper=gripper,
                target=self.cube.root_body,
                target_type="body",
                return_distance=True,
            )
            reward = 1.0 - float(np.tanh(10.0 * dist))
            reward += 1.0 if self._check_grasp(gripper=gripper, object_geoms=self.cube) else 0.0
        else:
            reward = 0.0
        return reward * self.reward_scale if self.reward_scale is not None else reward


class DoorCausal(Door):
    """Open a latched door that may be turned left or right, its handle high or low.

    As the paper's DoorCausal: robosuite's Door on a table at (-0.3, -0.5, 0.8), the door's yaw
    drawn around -pi/2 (here ±0.025 rad: the turn itself is the workspace feature), the handle's
    height a model edit of the latch body (nominal 0.05 m here, between the paper's 0.2 and
    -0.1), and an opened door worth 0.5 (robosuite's Door: 1) times ``reward_scale``.
    """

    placement_initializer: Any
    """Where the door is drawn (robosuite's sampler; ours unless one is passed)."""

    def _load_model(self) -> None:
        """Door's model on DoorCausal's table, with the door sampler and handle height above."""
        self.table_offset = DOOR_TABLE_OFFSET
        if self.placement_initializer is None:
            self.placement_initializer = UniformRandomSampler(
                name="ObjectSampler",
                x_range=[0.07, 0.09],
                y_range=[-0.01, 0.01],
                rotation=(-np.pi / 2 - DOOR_JITTER, -np.pi / 2 + DOOR_JITTER),
                rotation_axis="z",
                ensure_object_boundary_in_range=False,
                reference_pos=self.table_offset,
                rng=self.rng,
            )
        super()._load_model()
        latch = find_elements(
            root=self.door.worldbody,
            tags="body",
            attribs={"name": self.door.latch_body},
            return_first=True,
        )
        latch.set("pos", array_to_string(np.array([DOOR_HANDLE[0], 0.0, DOOR_HANDLE[1]])))

    def reward(self, action: Any = None) -> float:
        """Door's shaped reward, with 0.5 (not 1) for an opened door (the paper's DoorCausal)."""
        reward = super().reward(action)
        return 0.5 * reward if self._check_success() else reward
