"""PA-AD: the actor walks the victim's action furthest along the director's direction; the director
is trained once per victim (and cached), and the attack stays in its budget."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import advgame
from advgame.adversaries import PAADAttack, paad, specs
from advgame.adversaries.whitebox_walk import WhiteBoxAttackPolicy
from advgame.core.episodes import build_policies
from advgame.disruptors import ObservationDisruptor
from advgame.errors import ConfigError
from advgame.evaluation import (
    AdversarySetup,
    adversary_columns,
    evaluate,
    population_jobs,
    sb3_protagonist,
)

ADV = "observation_adversary"


class TanhVictim:
    """A small differentiable protagonist: a = tanh(B tanh(A s)), deterministic, no critic."""

    def __init__(self, n_obs: int = 11, n_act: int = 3) -> None:
        gen = torch.Generator().manual_seed(0)
        self.a = torch.randn(16, n_obs, generator=gen) / n_obs**0.5
        self.b = 0.5 * torch.randn(n_act, 16, generator=gen) / 4

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, observation: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return self.action_mean(torch.as_tensor(observation, dtype=torch.float32)[None])[
                0
            ].numpy()

    def action_mean(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.tanh(torch.tanh(obs @ self.a.T) @ self.b.T)

    def action_std(self) -> None:
        return None

    def value(self, obs: torch.Tensor) -> None:
        return None

    def q_value(self, obs: torch.Tensor, action: torch.Tensor) -> None:
        return None


def _in_budget(rng: np.random.Generator, n: int, norm: str) -> np.ndarray:
    """A uniform point of the unit box (L∞) or of the unit ball (L2)."""
    if norm == "linf":
        return rng.uniform(-1, 1, n)
    x = rng.standard_normal(n)
    return x / np.linalg.norm(x) * rng.uniform() ** (1 / n)


def _actor(victim: object, direction: np.ndarray, norm: str = "linf"):
    """A PA-AD actor bound to a Hopper game at a sense move, walking towards `direction`."""
    game = advgame.make("Hopper-v5", disruptors=[ObservationDisruptor(eps=0.05, norm=norm)])
    pols = build_policies(game, {"protagonist": victim})
    game.reset(seed=3)
    noop = game.agent_info(ADV).noop_action
    for _ in range(4):  # away from the initial pose
        game.play({a: noop if a == ADV else pols[a].act(game.observe(a)) for a in game.next_movers})
    assert game.move == "sense"
    actor = PAADAttack(steps=20).build(game.agent_info(ADV))
    WhiteBoxAttackPolicy.attach(actor, game, {"protagonist": pols["protagonist"]})  # no director
    actor.reset(0)
    actor.direction = np.asarray(direction, dtype=np.float64)
    return game, actor


@pytest.mark.parametrize("norm", ["linf", "l2"])
def test_the_actor_aligns_the_action_change_with_the_direction(norm: str) -> None:
    """The action change along the direction beats the best of 300 random points of the budget."""
    rng = np.random.default_rng(0)
    for direction in ([1.0, 0.0, 0.0], [-0.3, 0.8, 0.5]):
        _, actor = _actor(TanhVictim(), np.array(direction), norm)
        u = actor._attack_rows([actor], "protagonist")
        walk = actor._walk([actor], "protagonist")
        found = walk(u)[0][0]
        randoms = [walk(_in_budget(rng, 11, norm)[None])[0][0] for _ in range(300)]
        assert found >= max(randoms) - 1e-6
        assert found > 0  # the action moves the way the director points
        assert np.abs(u).max() <= 1.0 + 1e-9 and (norm == "linf" or np.linalg.norm(u) <= 1.0)


def test_the_numpy_walk_scores_and_differentiates_as_the_torch_walk(tmp_path: Path) -> None:
    import gymnasium as gym
    from stable_baselines3 import PPO

    path = tmp_path / "hopper.zip"
    PPO("MlpPolicy", gym.make("Hopper-v5"), seed=0, device="cpu").save(path)
    victim = sb3_protagonist(path, raw_observations=True)
    _, actor = _actor(victim, np.array([0.2, -0.7, 0.4]))
    u = np.random.default_rng(1).uniform(-1, 1, (1, 11))
    values, grad = actor._walk([actor], "protagonist")(u)
    t_values, t_grad = actor._torch_walk([actor], "protagonist")(u)
    assert actor._numpy_scorer([actor], actor.victims["protagonist"], np.zeros((1, 11))) is not None
    np.testing.assert_allclose(values, t_values, atol=1e-5)
    np.testing.assert_allclose(grad(), t_grad(), atol=1e-4)


def test_the_director_is_trained_once_and_the_column_stays_in_budget(
    pendulum_ppo: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ADVGAME_CACHE", str(tmp_path))
    prots = {"ppo": sb3_protagonist(pendulum_ppo, raw_observations=True)}
    cols = adversary_columns(
        "InvertedPendulum-v5", ["attack:pa-ad,samples=256"], protagonists=prots, threat="default"
    )
    assert list(cols) == ["nominal", "attack pa-ad"]
    jobs = population_jobs("InvertedPendulum-v5", prots, cols, seeds=(0, 1))
    table = evaluate(jobs, progress=False)
    attacked = [r for r in table.rows if r["adversary"] == "attack pa-ad"]
    assert len(attacked) == 2
    assert all(r["clipped"] == 0 for r in attacked)  # the actor's walk stays in the budget
    assert len(list((tmp_path / "paad").glob("*/observation_adversary.zip"))) == 1
    # Another table (as a new process would) loads the director: nothing is trained again.
    from advgame.adversaries import paad_director

    paad._DIRECTORS.clear()
    monkeypatch.setattr(paad_director, "train_director", lambda *a, **k: pytest.fail("trained"))
    again = evaluate(jobs, progress=False)
    assert [r["true_return"] for r in again.rows] == [r["true_return"] for r in table.rows]


def test_a_pool_trains_the_directors_ahead_in_its_workers(
    pendulum_pair: dict, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from advgame.adversaries import paad_director

    cache = tmp_path / "cache"
    attack = PAADAttack(director_steps=128, cache_dir=str(cache))
    setups = {"pa-ad": AdversarySetup({"preset": "default"}, {ADV: attack})}
    jobs = population_jobs("InvertedPendulum-v5", pendulum_pair, setups, seeds=(0, 1, 2))
    monkeypatch.setattr(paad, "_DIRECTORS", {})  # none trained in this process yet
    monkeypatch.setattr(paad_director, "train_director", lambda *a, **k: pytest.fail("in main"))
    table = evaluate(jobs, workers=2, progress=False)  # trained by the workers, loaded here
    assert len(list(cache.glob("*/observation_adversary.zip"))) == 2  # a director per victim
    assert not list(cache.glob("*.part-*"))
    assert len(table.rows) == 6 and all(r["clipped"] == 0 for r in table.rows)


def test_bad_uses_are_clear_errors() -> None:
    assert specs.adversary_spec("pa-ad") == PAADAttack()
    with pytest.raises(ConfigError, match="director_steps"):
        PAADAttack(director_steps=0)
    with pytest.raises(ConfigError, match="learning_rate"):
        PAADAttack(learning_rate=-1.0)
    game = advgame.make("Hopper-v5", preset="default")
    actor = PAADAttack().build(game.agent_info(ADV))
    with pytest.raises(ConfigError, match="not attached"):
        actor.act(np.zeros(11))
    with pytest.raises(ConfigError, match="director"):
        PAADAttack().row_objective(TanhVictim(), None, None)  # type: ignore[arg-type]
