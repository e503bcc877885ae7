"""Single-agent views: one agent of a game as a `gymnasium.Env`, the others frozen inside it.

A view lets any Stable-Baselines3 algorithm train either side: the protagonist against frozen
adversaries, or one adversary against a frozen protagonist (and frozen fellow adversaries).
One view step is one decision of the learning agent: the view plays the moves in between
(sense moves, steps its schedule skips) with the embedded policies and sums the learner's
reward over them. Under `SubprocVecEnv`, build views in the workers with `view_factory`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from advgame.core.episodes import (
    build_policies,
    reseed_policies,
    resume_schedules,
    schedule_positions,
)
from advgame.core.game import Game, Move
from advgame.core.numpy_net import NetCache, NumpyNet, sb3_modules
from advgame.core.policy import gaussian_mean
from advgame.errors import ConfigError

__all__ = ["SingleAgentView", "view_factory"]


class SingleAgentView(gym.Env):
    """`agent` of `game` as a Gymnasium env; every other agent plays its policy in `policies`.

    Adversaries missing from `policies` play their no-op (the nominal task); a protagonist
    must be given whenever the learner is an adversary.

    Reward of a step: the learner's reward summed over the moves it covered (a protagonist's
    observed reward; an adversary's ``-payoff``). Info: ``true_reward``, ``true_cost`` and
    ``payoff`` summed likewise, ``clipped`` (adversaries), and for protagonists the task's last
    info and the observed ``cost``.

    Example:
        >>> import advgame
        >>> game = advgame.make("Hopper-v5", disruptors={"observation": {"eps": 0.05}})
        >>> env = SingleAgentView(game, "protagonist")
        >>> obs, info = env.reset(seed=0)
        >>> env.observation_space.contains(obs)
        True

    """

    def __init__(self, game: Game, agent: str, policies: Mapping[str, Any] | None = None) -> None:
        if agent not in game.possible_agents:
            game.observation_space(agent)  # raises the "did you mean" error
        self.game = game
        self.agent = agent
        others = {a: p for a, p in (policies or {}).items() if a != agent}
        if policies and agent in policies:
            raise ConfigError(
                f"{agent!r} is the learner of this view; do not pass a policy for it."
            )
        self._learner = _Placeholder()
        probe = {agent: self._learner, **others}
        self.policies = {a: p for a, p in build_policies(game, probe).items() if a != agent}
        disruptor = game.disruptors.get(agent)
        if disruptor is not None and not disruptor.schedule.in_phase(game.phase):
            raise ConfigError(
                f"{agent!r} never acts in phase {game.phase!r} (its schedule is for "
                f"{disruptor.schedule.phase!r}); a view of it would have no decisions."
            )
        self.observation_space = game.observation_space(agent)
        self.action_space = game.action_space(agent)
        self.render_mode = getattr(getattr(game.task, "env", None), "render_mode", None)
        self._protagonist = agent in game.protagonists
        self._schedule = disruptor.schedule if disruptor is not None else None
        self._players: dict[frozenset[str], list[tuple[str, Any]]] = {}
        goal_reward = game.task.goal_reward if self._protagonist else None
        if goal_reward is not None:  # only then: SB3 takes any env with it for a goal env
            self.compute_reward = goal_reward
            """The task's own goal reward ``(achieved_goal, desired_goal, info)`` (goal-conditioned
            tasks), what HER relabels with: true goals in, the task's true reward out. Which goals
            HER passes is the replay buffer's choice; `advgame.agents.sb3.her`'s passes the true
            achieved goals the task put in ``info``, not the perturbed ones the protagonist saw."""

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[Any, dict]:
        """Reset the game and the embedded policies; play until the learner's first decision."""
        super().reset(seed=seed)
        reseed_policies(self.policies, seed)
        for _ in range(100):
            _, infos = self.game.reset(seed=seed, options=options)
            info: dict[str, Any] = dict(infos[self.agent])
            while self.game.agents and self.agent not in self.game.next_movers:
                self.game.play(self._others())
            if self.game.agents:
                return self.game.observe(self.agent), info
            seed = None  # the learner had no decision this episode; draw another
        raise ConfigError(f"{self.agent!r} got no decision in 100 episodes; check its schedule.")

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        """One decision of the learner, then the moves until its next one (or the episode end).

        `advgame.core.vector.VectorView` runs the same phases over N views in lockstep (the
        moves made by `advgame.core.lockstep.play_all`, then `_decided`, `_add`, `_finish`),
        batching the embedded policies' calls.
        """
        tally = self._decide(action, self._others())
        while self._waiting():
            self._between(self._others(), tally)
        return self._finish(tally)

    def _waiting(self) -> bool:
        """Whether the game has moves to play before the learner's next decision."""
        game = self.game
        return bool(game.agents) and self.agent not in game.next_movers

    def _decide(self, action: Any, others: dict[str, Any]) -> _Tally:
        """The learner's move; `others` holds the embedded policies' actions for it (`_players`)."""
        others[self.agent] = action
        return self._decided(self.game.play(others))

    def _decided(self, move: Move) -> _Tally:
        """What the learner's own move starts its step's tally with."""
        if not self._protagonist:
            tally = _Tally()
            self._add(move, tally)
            return tally
        # A protagonist's decision is one act move, and every move before its next decision is
        # a sense move, which adds nothing to its reward or info: nothing to sum here.
        assert move.rewards is not None and move.costs is not None and move.info is not None
        info = dict(move.info)
        get = info.get  # the task's info may hold these keys; `_add` adds to them
        info["cost"] = get("cost", 0.0) + move.costs[self.agent]
        info["true_reward"] = get("true_reward", 0.0) + move.reward
        info["true_cost"] = get("true_cost", 0.0) + move.cost
        info["payoff"] = get("payoff", 0.0) + move.payoff
        return _Tally(0.0 + move.rewards[self.agent], move.terminated, move.truncated, info)

    def _between(self, others: dict[str, Any], tally: _Tally) -> None:
        """One move between the learner's decisions (`_waiting`), with the others' actions."""
        if self._protagonist:
            sensed = self.game._sense(others)  # only sense moves: all actions built here
            assert sensed.rewards is None, "only sense moves come between protagonist decisions"
        else:
            self._add(self.game.play(others), tally)

    def _finish(self, tally: _Tally) -> tuple[Any, float, bool, bool, dict]:
        """The step's return once the learner is to decide again (or the episode ended)."""
        if tally.truncated and self._schedule is not None and self._schedule.exhausted(self.game.t):
            # The learner had no decision left when the time limit hit: for it the episode
            # ended with its last decision, so bootstrapping past the limit would be wrong.
            tally.terminated, tally.truncated = True, False
        obs = self.game.observe(self.agent)
        return obs, tally.reward, tally.terminated, tally.truncated, tally.info

    def _add(self, move: Move, tally: _Tally) -> None:
        """Add a move the learner did not decide (or an adversary's own) to the step's tally."""
        info = tally.info
        if self.agent in move.clipped:
            info["clipped"] = info.get("clipped", 0) + move.clipped[self.agent]
        if move.rewards is None:  # a sense move: no payoff accrues
            return
        assert move.costs is not None and move.info is not None
        if self._protagonist:
            info.update(move.info)
            tally.reward += move.rewards[self.agent]
            info["cost"] = info.get("cost", 0.0) + move.costs[self.agent]
        else:
            tally.reward -= move.payoff
        for key, value in (
            ("true_reward", move.reward),
            ("true_cost", move.cost),
            ("payoff", move.payoff),
        ):
            info[key] = info.get(key, 0.0) + value
        tally.terminated, tally.truncated = move.terminated, move.truncated

    def _players_now(self) -> list[tuple[str, Any]]:
        """The embedded (agent, policy) pairs of the next move: `Game.next_movers` but the learner."""
        movers = self.game.next_movers
        players = self._players.get(movers)
        if players is None:  # a few distinct mover sets per game: cache each one's policies
            players = [(a, self.policies[a]) for a in movers if a != self.agent]
            self._players[movers] = players
        return players

    def _others(self) -> dict[str, Any]:
        """The embedded policies' actions for the next move."""
        players = self._players_now()
        if not players:  # e.g. a protagonist's act move against sense-time adversaries only
            return {}
        observe = self.game.observe
        return {a: policy.act(observe(a)) for a, policy in players}

    def set_policies(self, policies: Mapping[str, Any]) -> None:
        """Swap some embedded policies (the training loop does this between phases).

        Works through `VecEnv.env_method` in worker processes; specs are built there.
        """
        if self.agent in policies:
            raise ConfigError(
                f"{self.agent!r} is the learner of this view; do not pass a policy for it."
            )
        probe = {self.agent: self._learner, **{a: p for a, p in self.policies.items()}, **policies}
        built = build_policies(self.game, probe)
        for a in policies:
            self.policies[a] = built[a]
        self._players.clear()

    def schedule_positions(self) -> dict[str, int]:
        """Where each embedded per-episode schedule is (`advgame.core.episodes.schedule_positions`)."""
        return schedule_positions(self.policies)

    def resume_schedules(self, positions: Mapping[str, int]) -> None:
        """Go on after `positions` (`advgame.core.episodes.resume_schedules`)."""
        resume_schedules(self.policies, positions)

    def set_observation_scale(self, target: str, std: Any) -> None:
        """Set the normalizer std of `target` for normalized-space observation budgets."""
        self.game.set_observation_scale(target, std)

    def bind_learner(self, model: Any, normalizer: Any = None) -> None:
        """Let attacks embedded in this view attack the live learner (`model`, behind `normalizer`).

        Only attacks read it (white-box observation attacks on the learner's observations);
        the learner's own actions still come from SB3.
        """
        self._learner.model, self._learner.normalizer = model, normalizer

    def render(self) -> Any:
        """Render the game's task base."""
        return self.game.render()

    def close(self) -> None:
        """Close the game."""
        self.game.close()


class _Tally:
    """What one view step accumulates over the moves it covers."""

    __slots__ = ("info", "reward", "terminated", "truncated")

    def __init__(
        self,
        reward: float = 0.0,
        terminated: bool = False,
        truncated: bool = False,
        info: dict[str, Any] | None = None,
    ) -> None:
        self.reward = reward
        self.terminated = terminated
        self.truncated = truncated
        self.info: dict[str, Any] = {} if info is None else info


class _Placeholder:
    """Stands in for the learner while the other agents' policies are built.

    It is also a white-box view of the learner (`advgame.core.policy.WhiteBox`), so an
    observation attack embedded in the view can attack the policy being trained: adversarial
    training on the current policy (Pattanaik et al. 2018). `SingleAgentView.bind_learner`
    binds the live SB3 model and its `VecNormalize` once they exist; PPO does not change its
    weights while it collects a rollout, so every rollout is attacked against the policy as it
    stands for that rollout.
    """

    def __init__(self) -> None:
        self.model: Any = None
        self.normalizer: Any = None
        self._numpy = NetCache()

    def reset(self, seed: int | None = None) -> None:
        """Unused."""

    def act(self, observation: Any) -> Any:
        """Unused."""
        raise AssertionError("the learner's placeholder policy is never queried")

    def _policy_input(self, obs: Any) -> Any:
        """Raw observations -> the learner's network input (its normalizer, as it is now)."""
        import torch

        if self.model is None:
            raise ConfigError(
                "An attack on the learner played before the learner was bound; train through "
                "advgame's loop (Side binds it), or call view.bind_learner(model, venv)."
            )
        if self.model.policy.training:
            self.model.policy.set_training_mode(False)
        stats = self._statistics()
        if stats is None:
            return obs
        mean, std, clip = stats
        mean_t = torch.as_tensor(mean, dtype=torch.float32)
        std_t = torch.as_tensor(std, dtype=torch.float32)
        return ((obs - mean_t) / std_t).clamp(-clip, clip)

    def _statistics(self) -> tuple[np.ndarray, np.ndarray, float] | None:
        """The learner's normalizer now: ``(mean, std, clip)``, or None if it normalizes nothing."""
        rms = getattr(self.normalizer, "obs_rms", None)
        if rms is None or not getattr(self.normalizer, "norm_obs", True):
            return None
        std = np.sqrt(rms.var + self.normalizer.epsilon)
        return rms.mean, std, float(self.normalizer.clip_obs)

    def numpy_net(self, head: str) -> NumpyNet | None:
        """The learner's current mean or value head as a `NumpyNet` (copied again after updates)."""
        if self.model is None:
            return None
        return self._numpy.get(head, sb3_modules(self.model_policy(), head), self._statistics())

    @property
    def batch_key(self) -> tuple | None:
        """Equal for the stand-ins of views bound to one learner: their attacks walk as one."""
        if self.model is None:
            return None
        return ("live-learner", id(self.model), id(self.normalizer))

    def action_mean(self, obs: Any) -> Any:
        """The learner's current mean action (a Gaussian policy's mean)."""
        policy, x = self.model_policy(), self._policy_input(obs)
        mean = gaussian_mean(policy, x)
        return policy.get_distribution(x).distribution.mean if mean is None else mean

    def action_std(self) -> Any:
        """The learner's current state-independent action std."""
        log_std = getattr(self.model_policy(), "log_std", None)
        return None if log_std is None else log_std.detach().exp()

    def value(self, obs: Any) -> Any:
        """The learner's current value estimate (a zero batch before it is bound)."""
        import torch

        if self.model is None:  # asked by an attack's check at build time: PPO has a value head
            return torch.zeros(obs.shape[0])
        return self.model_policy().predict_values(self._policy_input(obs)).squeeze(-1)

    def q_value(self, obs: Any, action: Any) -> Any:
        """``None``: on-policy learners (PPO) have no Q critic."""
        return None

    def model_policy(self) -> Any:
        """The bound model's policy (a clear error before binding)."""
        if self.model is None:
            self._policy_input(None)
        if hasattr(self.model.policy, "lstm_actor"):
            raise ConfigError(
                "Adversarial training on the current policy (PGD-AT) needs a feed-forward "
                "learner: a recurrent learner's memory lives in its own rollout, out of the "
                "attack's reach. Train with --protagonist-algo ppo or sa-ppo, or train a "
                "recurrent protagonist against a learned adversary (--method atla-lstm)."
            )
        if not hasattr(self.model.policy, "get_distribution"):
            raise ConfigError(
                f"Adversarial training on the current policy needs an on-policy Gaussian learner "
                f"(PPO); this learner is {type(self.model).__name__}."
            )
        return self.model.policy


def _build_view(
    scenario_id: str, agent: str, policies: Mapping[str, Any], make_kwargs: Mapping[str, Any]
) -> SingleAgentView:
    from advgame.core.registry import make

    return SingleAgentView(make(scenario_id, **make_kwargs), agent, policies)


def view_factory(
    scenario_id: str, agent: str, policies: Mapping[str, Any] | None = None, **make_kwargs: Any
) -> Callable[[], SingleAgentView]:
    """A picklable thunk that builds the game and the view (in a `SubprocVecEnv` worker).

    `policies` must be picklable: policy specs, or policies whose state pickles.

    Example:
        >>> from stable_baselines3.common.vec_env import DummyVecEnv
        >>> venv = DummyVecEnv([view_factory("Hopper-v5", "protagonist", preset="default")])
        >>> venv.observation_space.shape
        (11,)

    """
    return functools.partial(
        _build_view, scenario_id, agent, dict(policies or {}), dict(make_kwargs)
    )
