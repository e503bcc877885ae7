"""The built-in scenarios, one registry line each: importing this module registers them all.

The task bases and presets themselves are ``"module:attr"`` entry points, imported only when a
scenario is made; `advgame.core.registry` imports this module by name the first time it is
asked for a scenario.
"""

from __future__ import annotations

from advgame.core.registry import ScenarioSpec, register
from advgame.scenarios.mamujoco_list import register_all as _register_mamujoco
from advgame.scenarios.robotics_list import ENVS as _ROBOTICS

_MUJOCO = "advgame.scenarios.mujoco"
_BOX2D = "advgame.scenarios.box2d"


EXTRAS: dict[str, tuple[str, tuple[str, ...]]] = {
    "mujoco": ("", ()),
    "safe": ("", ()),
    "box2d": ("box2d", ("Box2D", "pygame")),
    # gymnasium-robotics 1.4.2 (robotics.py): goal-conditioned and dexterous manipulation
    **dict.fromkeys(
        ("maze", "fetch", "hand", "adroit", "kitchen"), ("robotics", ("gymnasium_robotics",))
    ),
}
"""Family -> (the advgame extra that installs it, the modules its task base imports)."""


def _gym(env_id: str, family: str, module: str, description: str) -> None:
    extra, requires = EXTRAS[family]
    register(
        ScenarioSpec(
            id=env_id,
            task=f"{module}:make_task",
            presets=f"{module}:presets",
            task_kwargs={"env_id": env_id},
            family=family,
            description=description,
            extra=extra,
            requires=requires,
        )
    )


# Gymnasium MuJoCo v5: observation, reward, action, dynamics and force disruptors.
_gym("Ant-v5", "mujoco", _MUJOCO, "quadruped locomotion")
_gym("HalfCheetah-v5", "mujoco", _MUJOCO, "planar running")
_gym("Hopper-v5", "mujoco", _MUJOCO, "planar one-legged hopping")
_gym("Walker2d-v5", "mujoco", _MUJOCO, "planar biped walking")
_gym("Swimmer-v5", "mujoco", _MUJOCO, "three-link swimming in a viscous fluid")
_gym("Humanoid-v5", "mujoco", _MUJOCO, "3D humanoid running")
_gym("HumanoidStandup-v5", "mujoco", _MUJOCO, "3D humanoid standing up")
_gym("Pusher-v5", "mujoco", _MUJOCO, "7-DoF arm pushing an object to a goal")
_gym("Reacher-v5", "mujoco", _MUJOCO, "2-link arm reaching a target")
_gym("InvertedPendulum-v5", "mujoco", _MUJOCO, "cart-pole balancing")
_gym("InvertedDoublePendulum-v5", "mujoco", _MUJOCO, "double cart-pole balancing")
# Safety MuJoCo: the MuJoCo v5 tasks with a velocity cost from the true state (safety.py).
_SAFETY = "advgame.scenarios.safety"
_gym("SafetyAnt-v5", "safe", _SAFETY, "Ant under a planar speed limit")
_gym("SafetyHalfCheetah-v5", "safe", _SAFETY, "HalfCheetah under a velocity limit")
_gym("SafetyHopper-v5", "safe", _SAFETY, "Hopper under a velocity limit")
_gym("SafetyWalker2d-v5", "safe", _SAFETY, "Walker2d under a velocity limit")
_gym("SafetySwimmer-v5", "safe", _SAFETY, "Swimmer under a velocity limit")
_gym("SafetyHumanoid-v5", "safe", _SAFETY, "Humanoid under a velocity limit")
_gym("SafetyHumanoidStandup-v5", "safe", _SAFETY, "HumanoidStandup under a rising-speed limit")
_gym("SafetyPusher-v5", "safe", _SAFETY, "Pusher under a tip-speed limit")
_gym("SafetyReacher-v5", "safe", _SAFETY, "Reacher under a tip-speed limit")
# Gymnasium Box2D: observation, reward and action disruptors.
_gym("BipedalWalker-v3", "box2d", _BOX2D, "2D biped over rough terrain")
_gym("CarRacing-v3", "box2d", _BOX2D, "top-down racing from 96x96 pixels")
_gym("LunarLander-v3", "box2d", _BOX2D, "lander with four discrete engine actions")
_gym("LunarLanderContinuous-v3", "box2d", _BOX2D, "lander with continuous throttles")


# gymnasium-robotics: Maze, Fetch, Shadow Hand, Adroit, Franka Kitchen (ids in robotics.py:
# ENVS in robotics_list.py, read without importing a simulator).
def _register_robotics() -> None:
    for env_id, (family, description) in _ROBOTICS.items():
        _gym(env_id, family, "advgame.scenarios.robotics", description)


_register_robotics()
# MaMuJoCo (gymnasium-robotics): one registry line per factorization, in mamujoco_list.py.
_register_mamujoco()


def _robosuite(env_name: str, description: str) -> None:
    register(
        ScenarioSpec(
            id=f"RS-{env_name}",
            task="advgame.scenarios.robosuite:make_task",
            presets="advgame.scenarios.robosuite:presets",
            task_kwargs={"env_name": env_name},
            family="robosuite",
            description=description,
            extra="robosuite",
            requires=("robosuite",),
        )
    )


# robosuite 1.5 (no rendering; flattened proprio + object state): the paper's twelve tasks.
_robosuite("Lift", "lift a cube (Panda)")
_robosuite("Stack", "stack one cube on another (Panda)")
_robosuite("NutAssembly", "fit two nuts on their pegs (Panda)")
_robosuite("PickPlace", "put four objects in their bins (Panda)")
_robosuite("Door", "open a door by its handle (Panda)")
_robosuite("Wipe", "wipe markings off a table (Panda)")
_robosuite("ToolHang", "hang a tool on a hook (Panda)")
_robosuite("TwoArmLift", "lift a pot by its two handles (two Pandas)")
_robosuite("TwoArmPegInHole", "insert a peg into a hole held by the other arm (two Pandas)")
_robosuite("TwoArmHandover", "hand a hammer from one arm to the other (two Pandas)")
_robosuite("TwoArmTransport", "move an object between two tables (two Pandas)")
_robosuite("MultiRobustDoor", "open a door while an adversarial second arm impedes (two Pandas)")
# The paper's causal tasks (robosuite_causal.py): a spurious feature correlated in training.
_robosuite("LiftCausal", "lift a cube whose observed colour goes with its side (Panda)")
_robosuite("DoorCausal", "open a door turned left or right, its handle high or low (Panda)")
