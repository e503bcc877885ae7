"""The safe-RL maximum-cost attack (Liu et al. 2023): a learned cost critic Q_c^π, attacked by PGD."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import advgame
from advgame.adversaries import MaxCostAttack, RobustSarsaAttack
from advgame.adversaries.specs import adversary_spec
from advgame.adversaries.whitebox_walk import WhiteBoxAttackPolicy
from advgame.core.episodes import rollout
from advgame.errors import ConfigError
from advgame.evaluation import adversary_columns
from advgame.workflows import zoo

pytestmark = pytest.mark.usefixtures("one_torch_thread")
SMALL = {"samples": 2000, "epochs": 4}
AGENT = "safetyhopper/ppo-lag"  # a released constrained agent that does incur cost


def test_the_cost_critic_is_its_own_fit_and_the_attack_stays_in_budget(tmp_path: Path) -> None:
    actors = zoo.load(AGENT)
    game = advgame.make("SafetyHopper-v5", preset="default", max_episode_steps=60)
    victim = actors["protagonist"].build(game.agent_info("protagonist"))
    # Q_c is fitted on the cost, not the reward: the two critics of one victim differ.
    mc = MaxCostAttack(cache_dir=str(tmp_path), **SMALL)
    rs = RobustSarsaAttack(cache_dir=str(tmp_path), **SMALL)
    q_c = mc.critic(game, "protagonist", victim)
    q_r = rs.critic(game, "protagonist", victim)
    assert len(list(tmp_path.glob("*.pt"))) == 2
    probe = torch.zeros(4, game.observation_space("protagonist").shape[0])
    with torch.no_grad():
        act = victim.action_mean(probe)
        assert not torch.equal(q_c(probe, act), q_r(probe, act))
    # Played: in the budget by construction (the disruptor clips nothing).
    [result] = rollout(game, {**actors, "observation_adversary": mc}, seed=0)
    assert result.length > 0 and result.clipped["observation_adversary"] == 0
    game.close()


def test_the_walk_raises_the_cost_critic_over_the_clean_action(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    gains: list[float] = []
    act_group = WhiteBoxAttackPolicy.act_group

    def spy(policies, observations):  # type: ignore[no-untyped-def]
        u = act_group(policies, observations)
        attack = policies[0]
        zero = np.zeros_like(u[0])
        gains.append(
            attack.objective_of("protagonist", u[0]) - attack.objective_of("protagonist", zero)
        )
        return u

    monkeypatch.setattr(WhiteBoxAttackPolicy, "act_group", staticmethod(spy))
    game = advgame.make("SafetyHopper-v5", preset="default", max_episode_steps=30)
    attack = MaxCostAttack(cache_dir=str(tmp_path), **SMALL)
    rollout(game, {**zoo.load(AGENT), "observation_adversary": attack}, seed=1)
    assert len(gains) == 30 and min(gains) >= 0 and max(gains) > 0
    game.close()


def test_max_cost_is_a_column_and_a_spec_and_refuses_costless_games(tmp_path: Path) -> None:
    cols = adversary_columns("SafetyHopper-v5", ["attack:max-cost,samples=100,epochs=1"])
    spec = cols["attack max-cost"].specs["observation_adversary"]
    assert isinstance(spec, MaxCostAttack) and (spec.samples, spec.epochs) == (100, 1)
    assert "attack max-cost" not in adversary_columns("SafetyHopper-v5", ["attacks"])
    assert isinstance(adversary_spec("max-cost"), MaxCostAttack)
    game = advgame.make("Hopper-v5", preset="default", max_episode_steps=5)
    ppo = zoo.load("hopper/ppo")
    with pytest.raises(ConfigError, match="computes no cost"):
        rollout(game, {"protagonist": ppo, "observation_adversary": MaxCostAttack(**SMALL)})
    game.close()
