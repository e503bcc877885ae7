"""The Robust Sarsa attack: Q^π of the frozen protagonist learned once, then attacked by PGD."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from advgame.adversaries import MADAttack, RobustSarsaAttack, sarsa_critic
from advgame.errors import ConfigError
from advgame.evaluation import (
    AdversarySetup,
    adversary_columns,
    evaluate,
    population_jobs,
    sb3_protagonist,
)

SMALL = {"samples": 3000, "epochs": 8}


@pytest.fixture
def pendulum(pendulum_ppo: Path) -> Path:
    """The session's small PPO on InvertedPendulum-v5 (`pendulum_ppo`)."""
    return pendulum_ppo


def _setups(cache: Path) -> dict[str, AdversarySetup]:
    rs = RobustSarsaAttack(cache_dir=str(cache), **SMALL)
    return {
        "nominal": AdversarySetup.nominal(),
        "rs": AdversarySetup({"preset": "default"}, {"observation_adversary": rs}),
    }


def test_the_critic_is_learned_once_and_the_attack_stays_in_budget(
    pendulum: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    prots = {"ppo": sb3_protagonist(pendulum, raw_observations=True)}
    jobs = population_jobs("InvertedPendulum-v5", prots, _setups(tmp_path), seeds=(0, 1))
    table = evaluate(jobs, progress=False)
    assert len(list(tmp_path.glob("*.pt"))) == 1
    assert all(r["clipped"] == 0 for r in table.rows)  # in the budget by construction
    # A second table (a new process would do the same) loads the critic: nothing is learned.
    sarsa_critic_calls = []
    monkeypatch.setattr(sarsa_critic, "fit_sarsa", lambda *a, **k: sarsa_critic_calls.append(a))
    from advgame.adversaries import robust_sarsa

    robust_sarsa._CRITICS.clear()
    again = evaluate(jobs, progress=False)
    assert sarsa_critic_calls == []
    assert [r["true_return"] for r in again.rows] == [r["true_return"] for r in table.rows]


def test_a_pool_fits_the_critics_ahead_in_its_workers(
    pendulum_pair: dict, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cache = tmp_path / "cache"
    jobs = population_jobs("InvertedPendulum-v5", pendulum_pair, _setups(cache), seeds=(0, 1))
    from advgame.adversaries import robust_sarsa

    monkeypatch.setattr(robust_sarsa, "_CRITICS", {})  # none fitted in this process yet
    monkeypatch.setattr(sarsa_critic, "fit_sarsa", lambda *a, **k: pytest.fail("fitted in main"))
    table = evaluate(jobs, workers=2, progress=False)  # fitted by the workers, loaded here
    assert len(list(cache.glob("*.pt"))) == 2
    assert len(table.rows) == 8


def test_the_learned_q_ranks_states_by_their_returns(pendulum: Path) -> None:
    """Q^π(s, μ(s)) of the start states tracks their discounted returns (Sarsa learned Q^π)."""
    from advgame.core.registry import make

    game = make("InvertedPendulum-v5", disruptors={})
    policy = sb3_protagonist(pendulum, raw_observations=True).build(game.agent_info("protagonist"))
    fields = dict(RobustSarsaAttack(**SMALL).__dict__)
    fit = {k: fields[k] for k in ("samples", "epochs", "batch_size", "hidden", "gamma", "lr")}
    fit |= {k: fields[k] for k in ("reg", "reg_eps", "reg_steps", "seed")}
    q = sarsa_critic.fit_sarsa("InvertedPendulum-v5", "protagonist", policy, **fit)
    data = sarsa_critic.collect("InvertedPendulum-v5", "protagonist", policy, 2000, seed=123)
    # discounted return to go of every visited state, episode by episode
    ret = np.zeros(len(data["rew"]))
    g = 0.0
    for i in range(len(ret) - 1, -1, -1):
        last = (
            data["done"][i]
            or i == len(ret) - 1
            or not np.array_equal(data["next"][i], data["obs"][i + 1])
        )
        g = data["rew"][i] + (0.0 if last else 0.99 * g)
        ret[i] = g
    with torch.no_grad():
        values = q(torch.as_tensor(data["obs"]), torch.as_tensor(data["act"])).numpy()
    assert np.corrcoef(values, ret)[0, 1] > 0.5
    game.close()


def test_rs_is_a_column_of_the_attack_suite_with_its_options() -> None:
    cols = adversary_columns("Hopper-v5", ["attacks,samples=100,epochs=1"])
    spec = cols["attack rs"].specs["observation_adversary"]
    assert isinstance(spec, RobustSarsaAttack) and (spec.samples, spec.epochs) == (100, 1)
    assert "attack mad" in cols and isinstance(
        cols["attack mad"].specs["observation_adversary"], MADAttack
    )


@pytest.mark.parametrize(
    "bad", [{"samples": 0}, {"gamma": 1.5}, {"reg": -1.0}, {"hidden": ()}, {"reg_eps": "x"}]
)
def test_bad_settings_are_config_errors(bad: dict) -> None:
    with pytest.raises(ConfigError, match="RobustSarsaAttack"):
        RobustSarsaAttack(**bad)
