"""How much reward the causal tasks pay per step, against SAC's entropy bonus (issue 68).

For each scene of ``RS-DoorCausal`` (the four pairings of the door's turn and the handle's
height), robosuite's own Door (``RS-Door``) and ``RS-LiftCausal`` (the cube on either side),
plays ``--episodes`` seeded episodes of ``--steps`` steps under three protagonists: ``zero``
(all-zero actions), ``random`` (uniform on [-1, 1]^7: what SAC's start steps play) and
``reach`` (a P-controller on the observed gripper-to-target vector, gripper open: it shows
that the shaped reward reaches the target). Printed per scene and protagonist (means over the
episodes): the gripper's initial distance to the handle (cube), the episode return, the mean
and largest per-step reward, and the closest the gripper came. Then the entropy bonus of
SB3's SAC at initialisation, ``α·E[-log π]`` for a 7-dimensional action at the fixed
``α = 0.2`` of the paper's SAC table (`advgame.agents.SACConfig`), and its ratio to each
task's random-play reward per step.
Run: ``python benchmarks/causal_rewards.py [--episodes 3] [--steps 300]``.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

import advgame

SCENES: list[tuple[str, tuple[float, float] | None, str]] = [
    ("RS-DoorCausal", (1.0, 1.0), "DoorCausal hhl: left, high handle"),
    ("RS-DoorCausal", (-1.0, -1.0), "DoorCausal hhl: right, low handle"),
    ("RS-DoorCausal", (1.0, -1.0), "DoorCausal hhr: left, low handle"),
    ("RS-DoorCausal", (-1.0, 1.0), "DoorCausal hhr: right, high handle"),
    ("RS-Door", None, "robosuite Door"),
    ("RS-LiftCausal", (1.0, 1.0), "LiftCausal: y > 0, red"),
    ("RS-LiftCausal", (-1.0, -1.0), "LiftCausal: y < 0, green"),
]
POLICIES = ("zero", "random", "reach")


def to_target(env: Any) -> np.ndarray:
    """The vector from the gripper to the handle (Door tasks) or to the cube (Lift tasks)."""
    obs = env._get_observations(force_update=False)
    if "handle_to_eef_pos" in obs:
        return np.asarray(obs["handle_to_eef_pos"])  # handle - eef
    return np.asarray(obs["gripper_to_cube_pos"])  # robosuite 1.5: cube - eef, despite the name


def episode(
    sid: str, scene: tuple[float, float] | None, policy: str, seed: int, steps: int
) -> tuple[float, ...]:
    """One episode: initial distance, return, mean and max reward, closest distance."""
    if scene is None:
        game = advgame.make(sid, disruptors={}, max_episode_steps=steps)
    else:
        game = advgame.make(sid, preset="adversarial", max_episode_steps=steps)
    game.reset(seed=seed)
    if scene is not None:
        game.play({"workspace_adversary": np.array(scene, dtype=np.float32)})
    env = game.task.env
    rng = np.random.default_rng(seed)
    d0 = float(np.linalg.norm(to_target(env)))
    rewards, dists = [], []
    for _ in range(steps):
        if policy == "zero":
            a = np.zeros(7)
        elif policy == "random":
            a = rng.uniform(-1.0, 1.0, 7)
        else:
            a = np.zeros(7)
            a[:3] = np.clip(10.0 * to_target(env), -1.0, 1.0)
            a[6] = -1.0
        move = game.play({"protagonist": a.astype(np.float32)})
        rewards.append(move.reward)
        dists.append(float(np.linalg.norm(to_target(env))))
    game.close()
    r = np.asarray(rewards)
    return d0, float(r.sum()), float(r.mean()), float(r.max()), float(min(dists))


def entropy_bonus(alpha: float = 0.2, n: int = 4096) -> float:
    """``α·E[-log π]`` of SB3's SAC actor at initialisation, 7-dim actions, 64-dim observations."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import SAC

    class Blank(gym.Env):
        observation_space = gym.spaces.Box(-np.inf, np.inf, (64,))
        action_space = gym.spaces.Box(-1.0, 1.0, (7,))

        def reset(self, seed: int | None = None, options: dict | None = None) -> Any:
            return np.zeros(64, np.float32), {}

        def step(self, action: Any) -> Any:
            return np.zeros(64, np.float32), 0.0, False, False, {}

    torch.manual_seed(0)
    model = SAC("MlpPolicy", Blank(), policy_kwargs={"net_arch": [64, 64]}, seed=0, device="cpu")
    with torch.no_grad():
        _, logp = model.actor.action_log_prob(torch.randn(n, 64))
    return alpha * float(-logp.mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--steps", type=int, default=300)
    args = parser.parse_args()
    print("scene | policy | d0 (m) | return | mean r/step | max r | closest (m)")
    random_rate: dict[str, list[float]] = {}
    for sid, scene, name in SCENES:
        for policy in POLICIES:
            rows = [episode(sid, scene, policy, s, args.steps) for s in range(args.episodes)]
            d0, ret, mean, top, closest = np.mean(rows, axis=0)
            print(
                f"{name} | {policy} | {d0:.3f} | {ret:.3f} | {mean:.5f} | {top:.4f} | {closest:.3f}"
            )
            if policy == "random":
                random_rate.setdefault(sid, []).append(mean)
    bonus = entropy_bonus()
    print(f"SAC at initialisation, alpha 0.2: alpha*E[-log pi] = {bonus:.3f} per step")
    for sid, rates in random_rate.items():
        r = float(np.mean(rates))
        print(f"{sid}: random play {r:.5f} per step; entropy bonus / reward = {bonus / r:.0f}")


if __name__ == "__main__":
    main()
