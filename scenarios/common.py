"""Preset builders shared by the single-agent task families (the paper's settings)."""

from __future__ import annotations

from advgame.adversaries import GaussianAdversary, UniformAdversary
from advgame.core.registry import Preset
from advgame.core.schedule import Schedule
from advgame.core.task import GymTask
from advgame.disruptors import ActionDisruptor, ObservationDisruptor, RewardDisruptor

__all__ = ["gaussian_presets", "make_task"]


def make_task(env_id: str, **kwargs: object) -> GymTask:
    """A Gymnasium env as a single-protagonist task base.

    Gymnasium's MuJoCo v5 tasks get `advgame.scenarios.mujoco_batch.BatchedGymTask`, which
    steps the simulators of alike games moving together as one batch.
    """
    from advgame.scenarios.mujoco_formulas import FORMULAS

    if env_id in FORMULAS:
        from advgame.scenarios.mujoco_batch import BatchedGymTask

        return BatchedGymTask(env_id, **kwargs)
    return GymTask(env_id, **kwargs)  # type: ignore[arg-type]


def gaussian_presets(action: ActionDisruptor | None = None) -> dict[str, Preset]:
    """The paper's random-mode settings on state (S) and action (A), and its frequency attacks.

    ``state-gauss-σ``/``action-gauss-σ``: unbounded N(0, σ) noise every step (σ = 0.1, 0.15).
    ``state-uniform-0.2-0.8``: U[0.2, 0.8] state noise, bounded at 0.8.
    ``state-gauss-0.1-100F``: N(0, 0.1) state noise every 100 steps.
    ``state-gauss-0.1-post``: N(0, 0.1) state noise at evaluation only (post-training).
    """
    obs_unb = ObservationDisruptor(bounded=False)
    out: dict[str, Preset] = {}
    for sigma in (0.1, 0.15):
        out[f"state-gauss-{sigma}"] = Preset(
            (obs_unb,),
            {"observation_adversary": GaussianAdversary(std=sigma)},
            f"paper: state noise N(0, {sigma}) every step",
        )
        if action is None:
            out[f"action-gauss-{sigma}"] = Preset(
                (ActionDisruptor(bounded=False),),
                {"action_adversary": GaussianAdversary(std=sigma)},
                f"paper: action noise N(0, {sigma}) every step",
            )
    out["state-uniform-0.2-0.8"] = Preset(
        (ObservationDisruptor(eps=0.8),),
        {"observation_adversary": UniformAdversary(0.2, 0.8)},
        "paper: state noise U[0.2, 0.8] every step",
    )
    out["state-gauss-0.1-100F"] = Preset(
        (ObservationDisruptor(bounded=False, schedule=Schedule.every_n(100)),),
        {"observation_adversary": GaussianAdversary(std=0.1)},
        "paper: state noise N(0, 0.1) every 100 steps",
    )
    out["state-gauss-0.1-post"] = Preset(
        (ObservationDisruptor(bounded=False, schedule=Schedule(phase="eval")),),
        {"observation_adversary": GaussianAdversary(std=0.1)},
        "paper: state noise N(0, 0.1) at evaluation only (post-training setting)",
    )
    out["reward-gauss-0.1"] = Preset(
        (RewardDisruptor(bounded=False),),
        {"reward_adversary": GaussianAdversary(std=0.1)},
        "paper: observed-reward noise N(0, 0.1)",
    )
    return out
