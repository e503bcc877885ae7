"""The Game's contract, part two: true payoffs and determinism.

A reward (or cost) disruptor changes only what the protagonist observes; adversaries are paid the
negative of the true (weighted) payoff; and seeded rollouts are identical step by step, with
nothing leaking across episodes (invariant 5). All on a real simulator (MuJoCo Hopper-v5).
"""

from __future__ import annotations

from typing import Any

import numpy as np

import advgame
from advgame.adversaries import GaussianAdversary
from advgame.core.episodes import rollout
from advgame.core.policy import AgentInfo
from advgame.disruptors import RewardDisruptor
from tests._game_helpers import ACT, DYN, FORCE, OBS, REW, P, ProtagonistRng, hopper


# -- (c) reward disruptor vs true reward, zero-sum on the true payoff ---------------------------
def test_reward_disruptor_changes_only_what_the_protagonist_observes() -> None:
    game = hopper([RewardDisruptor(eps=0.5)], steps=25)
    nominal = hopper([], steps=25)
    act_a, act_b = ProtagonistRng(game, 8), ProtagonistRng(nominal, 8)
    game.reset(seed=3)
    nominal.reset(seed=3)
    changed = steps = 0
    while game.agents:
        steps += 1
        u = 1.0 if game.t % 2 == 0 else -4.0  # -4 is clipped to -1
        _, rewards, _, _, infos = game.step({P: act_a(), REW: np.array([u], dtype=np.float32)})
        _, nom_rewards, _, _, nom_infos = nominal.step({P: act_b()})
        true = nom_rewards[P]
        assert infos[P]["true_reward"] == true == nom_infos[P]["true_reward"]
        assert rewards[P] == true + 0.5 * max(u, -1.0)
        assert infos[P]["payoff"] == true
        assert rewards[REW] == -true  # paid on the true payoff, not the observed reward
        assert infos[REW]["clipped"] == (1 if u < -1 else 0)
        changed += rewards[P] != true
    assert not nominal.agents
    assert steps >= 5 and changed == steps


def test_cost_disruptor_and_weighted_payoff() -> None:
    game = hopper(
        [RewardDisruptor(eps=0.25, signal="cost")], steps=20, cost_key="x_velocity", cost_weight=0.5
    )
    assert game.adversaries == ("cost_adversary",) and game.cost_weight == 0.5
    act = ProtagonistRng(game, 9)
    game.reset(seed=1)
    nonzero = 0
    while game.agents:
        _, rewards, _, _, infos = game.step({P: act(), "cost_adversary": np.ones(1, np.float32)})
        info = infos[P]
        assert info["true_cost"] == info["x_velocity"]
        assert info["cost"] == info["true_cost"] + 0.25
        assert rewards[P] == info["true_reward"]
        assert info["payoff"] == info["true_reward"] - 0.5 * info["true_cost"]
        assert rewards["cost_adversary"] == -info["payoff"]
        nonzero += info["true_cost"] != 0.0
    assert nonzero > 0


# -- (d) determinism (invariant 5) ----------------------------------------------------------
class _Recorder:
    def __init__(self, inner: Any, log: list[np.ndarray]) -> None:
        self.inner, self.log = inner, log

    def reset(self, seed: int | None = None) -> None:
        self.inner.reset(seed)

    def act(self, observation: Any) -> Any:
        self.log.append(np.array(observation, copy=True))
        return self.inner.act(observation)


class _Recording:
    """A PolicySpec wrapping another, recording every observation its policy acts on."""

    def __init__(self, spec: Any, log: list[np.ndarray]) -> None:
        self.spec, self.log = spec, log

    def build(self, info: AgentInfo) -> _Recorder:
        return _Recorder(self.spec.build(info), self.log)


class _RandomProtagonist:
    def __init__(self, space: Any, log: list[np.ndarray]) -> None:
        self.space, self.log = space, log
        self.rng = np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def act(self, observation: Any) -> np.ndarray:
        self.log.append(np.array(observation, copy=True))
        return self.rng.uniform(self.space.low, self.space.high).astype(self.space.dtype)


ADVERSARY_NOISE = {
    OBS: GaussianAdversary(std=0.05),
    REW: GaussianAdversary(std=0.05),
    ACT: GaussianAdversary(std=0.05),
    DYN: GaussianAdversary(mean=1.0, std=0.1),  # relative factors around nominal
    FORCE: GaussianAdversary(std=2.0),
}


def _seeded_rollout(game: advgame.Game, seed: int) -> tuple[list, dict[str, list[np.ndarray]]]:
    logs: dict[str, list[np.ndarray]] = {a: [] for a in game.possible_agents}
    policies: dict[str, Any] = {a: _Recording(s, logs[a]) for a, s in ADVERSARY_NOISE.items()}
    policies[P] = _RandomProtagonist(game.action_space(P), logs[P])
    return rollout(game, policies, seed=seed, episodes=2), logs


def _same_logs(a: dict[str, list[np.ndarray]], b: dict[str, list[np.ndarray]]) -> bool:
    return a.keys() == b.keys() and all(
        len(a[k]) == len(b[k])
        and all(np.array_equal(x, y) for x, y in zip(a[k], b[k], strict=True))
        for k in a
    )


def test_seeded_rollouts_are_identical_step_by_step() -> None:
    game1 = advgame.make("Hopper-v5", preset="full", max_episode_steps=60)
    game2 = advgame.make("Hopper-v5", preset="full", max_episode_steps=60)
    assert set(game1.adversaries) == set(ADVERSARY_NOISE)
    res1, logs1 = _seeded_rollout(game1, 11)
    res2, logs2 = _seeded_rollout(game2, 11)
    assert res1 == res2
    assert all(r.length > 0 for r in res1)
    assert len(logs1[P]) == sum(r.length for r in res1)
    assert len(logs1[OBS]) == len(logs1[P])  # a sense move before every protagonist step
    assert len(logs1[DYN]) == 2  # per-episode schedule: once per episode
    assert _same_logs(logs1, logs2)
    # the protagonist acted on perturbed observations (the noise is live)
    assert not all(np.array_equal(p, s) for p, s in zip(logs1[P], logs1[OBS], strict=True))

    # the same game played again from the same seed: nothing leaks across episodes
    res3, logs3 = _seeded_rollout(game1, 11)
    assert res3 == res1 and _same_logs(logs3, logs1)

    res4, logs4 = _seeded_rollout(game2, 12)
    assert res4 != res1
    assert not np.array_equal(logs4[P][0], logs1[P][0])
    assert not _same_logs(logs4, logs1)
