"""Training a PA-AD director: the observation adversary's views with a direction as action.

`DirectorEnv` turns the observation adversary's `advgame.core.vector.VectorView` into the
director's environment, and `train_director` trains one with PPO against a frozen victim
(`advgame.adversaries.paad.PAADAttack` calls it the first time it meets a victim).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnvWrapper

from advgame.adversaries.whitebox_walk import WhiteBoxAttackPolicy
from advgame.core.policy import AgentInfo
from advgame.errors import ConfigError

if TYPE_CHECKING:
    from advgame.core.game import Game

__all__ = ["DirectorEnv", "director_info", "train_director"]


def director_info(game: Game, agent: str, target: str) -> AgentInfo:
    """What a director of `agent` plays: its observations, a direction in `target`'s actions."""
    from gymnasium import spaces

    shape = game.action_space(target).shape
    return AgentInfo(agent, game.observation_space(agent), spaces.Box(-1.0, 1.0, shape, np.float32))


class DirectorEnv(VecEnvWrapper):
    """The observation adversary's views with PA-AD's action: a direction in the victim's actions.

    Wraps a `advgame.core.vector.VectorView` of the observation adversary (its views embed the
    frozen victim). Each step takes one direction per view (``Box(-1, 1, victim action
    shape)``), turns it into the adversary's perturbation by the actor's walk on every view at
    once, and steps the views with it: what the director learns on. Observations and rewards
    are the views' (the true state; minus the protagonists' payoff).

    Args:
        venv: the adversary's `VectorView`.
        spec: the attack (`advgame.adversaries.paad.PAADAttack`: the actor's walk settings);
            ``spec.build(info)`` gives each view's actor.
        seed: seeds view ``i``'s random starts with ``seed + i``.

    """

    def __init__(self, venv: Any, spec: Any, seed: int = 0) -> None:
        self.attackers: list[Any] = []
        space = None
        for i, view in enumerate(venv.envs):
            info = view.game.agent_info(view.agent)
            pol = spec.build(info)
            targets = pol.disruptor.targets
            if len(targets) != 1:
                raise ConfigError(
                    f"A PA-AD director plays one target; {view.agent!r} perturbs {list(targets)}."
                )
            WhiteBoxAttackPolicy.attach(pol, view.game, {t: view.policies.get(t) for t in targets})
            pol.reset(seed + i)
            self.attackers.append(pol)
            space = director_info(view.game, view.agent, targets[0]).action_space
        super().__init__(venv, action_space=space)

    def reset(self) -> Any:
        """Reset the views."""
        return self.venv.reset()

    def step_async(self, actions: np.ndarray) -> None:
        """Walk every view's perturbation towards its direction, then step the views with them."""
        for pol, d in zip(self.attackers, np.asarray(actions, dtype=np.float64), strict=True):
            pol.direction = np.clip(d.reshape(-1), -1.0, 1.0)
        # the base walk, not `_PAADPolicy.act_group`: the directions are the learner's actions,
        # and the walk reads each game's true observation itself
        self.venv.step_async(_walk_all(self.attackers))

    def step_wait(self) -> Any:
        """The views' step results."""
        return self.venv.step_wait()


def _walk_all(attackers: list[Any]) -> np.ndarray:
    """Every view's perturbation: one walk when the views' victims share a ``batch_key``.

    Otherwise (a recurrent victim, whose key is None: each view's copy carries its own
    memory) each view walks alone, with its own victim.
    """
    keys = {a.batch_key for a in attackers}
    if len(attackers) > 1 and (None in keys or len(keys) > 1):
        return np.concatenate([WhiteBoxAttackPolicy.act_group([a], [None]) for a in attackers])
    return WhiteBoxAttackPolicy.act_group(attackers, [None] * len(attackers))


def train_director(
    spec: Any,
    scenario: str,
    disruptor: Any,
    agent: str,
    target: str,
    victim: Any,
    folder: Path,
    *,
    phase: str = "eval",
) -> Any:
    """Train a PA-AD director against `victim` and save it in `folder`; return its spec.

    Args:
        spec: the attack (walk and training settings).
        scenario: the registered scenario.
        disruptor: the observation disruptor's spec the director plays (budget and norm).
        agent: that disruptor's adversary agent.
        target: the protagonist it perturbs (`victim` plays it).
        victim: the frozen protagonist policy (a `WhiteBox`).
        folder: where the director's model and normalizer are written.
        phase: the game phase to train in (the attack's evaluation phase).

    """
    from advgame.agents.common.side import Side
    from advgame.agents.common.stats import normalized
    from advgame.agents.sb3.config import PPOConfig
    from advgame.core.vector import VectorView
    from advgame.core.views import view_factory

    rollout = min(2048, spec.director_steps)  # PPO's rollout, shorter for a tiny budget
    learner = PPOConfig(
        learning_rate=float(spec.learning_rate),
        ent_coef=float(spec.ent_coef),
        n_steps=rollout,
        batch_size=min(64, rollout),
    )
    fn = view_factory(scenario, agent, {target: victim}, disruptors=[disruptor], phase=phase)
    views = VectorView([fn])
    std = getattr(victim, "observation_std", None)
    if std is not None:  # a normalized-space budget is measured in the victim's normalizer
        views.env_method("set_observation_scale", target, std)
    venv = normalized(DirectorEnv(views, spec, seed=spec.seed), True, learner.gamma)
    side = Side(agent, learner, [], spec.seed, spec.director_steps, venv=venv)
    try:
        side.learn(spec.director_steps)
        return side.save(Path(folder))
    finally:
        side.close()
