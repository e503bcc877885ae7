"""Population sampling and the validation of training configs.

Latest, fictitious and uniform sampling of a hand-built population, reproducible from the
generator, with clear errors, and the population file's round trip; bad `TrainConfig` values,
learner hyper-parameters and learned adversaries are `ConfigError`s that name the problem, and the
rollout-size warning names only the sides that train.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from advgame.adversaries import ConstantAdversary, ZeroAdversary
from advgame.errors import ConfigError
from advgame.training import TrainConfig, learner_config, train
from advgame.training.population import Member, Population
from tests._training_helpers import AGENT, config

# -- population sampling ----------------------------------------------------------------------


def hand_built_population() -> Population:
    pop = Population()
    pop.add(Member(f"{AGENT}:noop", "adversary", AGENT, ZeroAdversary(), 0, learned=False))
    for i in range(4):
        pop.add(Member(f"{AGENT}@{i}", "adversary", AGENT, ConstantAdversary((0.1 * i,)), i))
    pop.add(Member("other@0", "adversary", "action_adversary", ZeroAdversary(), 0))
    return pop


def draws(how: str, n: int = 400, seed: int = 0) -> list[str]:
    pop, rng = hand_built_population(), np.random.default_rng(seed)
    return [pop.sample(AGENT, how, rng).id for _ in range(n)]


def test_latest_sampling_is_always_the_newest_member() -> None:
    assert set(draws("latest")) == {f"{AGENT}@3"}
    pop = hand_built_population()
    pop.add(Member(f"{AGENT}@4", "adversary", AGENT, ZeroAdversary(), 4))
    assert pop.sample(AGENT, "latest", np.random.default_rng(0)).id == f"{AGENT}@4"


def test_fictitious_sampling_never_draws_an_unlearned_member() -> None:
    counts = Counter(draws("fictitious"))
    assert set(counts) == {f"{AGENT}@{i}" for i in range(4)}  # every snapshot, never the no-op
    assert min(counts.values()) > 400 / 4 * 0.6


def test_uniform_sampling_covers_every_member_of_the_agent() -> None:
    counts = Counter(draws("uniform"))
    assert set(counts) == {f"{AGENT}:noop", *(f"{AGENT}@{i}" for i in range(4))}
    assert min(counts.values()) > 400 / 5 * 0.6


def test_sampling_is_reproducible_from_the_generator() -> None:
    assert draws("uniform", seed=7) == draws("uniform", seed=7)
    assert draws("uniform", seed=7) != draws("uniform", seed=8)


def test_sampling_errors_name_the_problem() -> None:
    pop, rng = hand_built_population(), np.random.default_rng(0)
    with pytest.raises(ConfigError, match="'best'"):
        pop.sample(AGENT, "best", rng)
    with pytest.raises(ConfigError, match="force_adversary"):
        pop.sample("force_adversary", "latest", rng)
    with pytest.raises(ConfigError, match="@0"):
        pop.add(Member(f"{AGENT}@0", "adversary", AGENT, ZeroAdversary(), 0))


def test_population_file_round_trip(tmp_path: Path) -> None:
    pop = hand_built_population()
    pop.save(tmp_path / "population.json")
    back = Population.load(tmp_path / "population.json")
    assert [m.to_dict() for m in back] == [m.to_dict() for m in pop]
    assert back.members[2].spec == ConstantAdversary((0.1,))


# -- config validation ------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("iterations", 0),
        ("iterations", 2.5),
        ("protagonist_steps", -128),
        ("adversary_steps", -1),
        ("warmup_steps", -64),
        ("eval_episodes", -1),
        ("n_envs", 0),
        ("snapshot_every", 0),
        ("sampling", "best-response"),
        ("train_budget_scale", 0.0),
        ("train_budget_scale", -0.5),
        ("train_budget_scale", "half"),
        ("vec_env", "subprocess"),
        ("protagonist_algo", "dqn"),
        ("adversary_algo", "a2c"),
        ("learned", "observation_adversary"),
    ],
)
def test_bad_train_config_values_raise_config_error(field: str, value: Any) -> None:
    with pytest.raises(ConfigError) as err:
        TrainConfig(**{field: value})
    assert repr(value) in str(err.value) or str(value) in str(err.value)
    assert field in str(err.value)


def test_unknown_learner_hyper_parameters_suggest_the_nearest_name(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match='Did you mean "n_steps"'):
        learner_config("ppo", {"n_step": 64})
    with pytest.raises(ConfigError, match='Did you mean "learning_starts"'):
        learner_config("sac", {"learning_start": 32})
    with pytest.raises(ConfigError, match="'n_steps'") as err:
        train(TrainConfig(adversary_hparams={"nsteps": 64}), tmp_path / "run", progress=False)
    assert "nsteps" in str(err.value)
    assert not (tmp_path / "run" / "state.json").exists()


def test_bad_learner_hyper_parameter_values_raise_config_error() -> None:
    with pytest.raises(ConfigError, match=r"n_steps.* 0\b"):
        learner_config("ppo", {"n_steps": 0})
    with pytest.raises(ConfigError, match=r"buffer_size.*-5"):
        learner_config("sac", {"buffer_size": -5})
    with pytest.raises(ConfigError, match="'mappo2'"):
        learner_config("mappo2", None)


def test_learned_must_name_adversaries_of_the_game(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="force_adversary"):
        train(config("atla", learned=["force_adversary"]), tmp_path / "run", progress=False)


def test_the_rollout_size_warning_names_only_sides_that_train(caplog, tmp_path: Path) -> None:
    """A whole-rollout mismatch is warned for each side that trains; PPO trains no adversary."""
    import logging

    from advgame.training.loop import Run
    from advgame.training.trainer import Trainer

    odd = {"n_steps": 48}  # TINY's phases are not whole rollouts of 48 steps
    for method, sides in (("ppo", {"protagonist"}), ("atla", {"protagonist", "adversary"})):
        caplog.clear()
        cfg = config(method, protagonist_hparams=odd, adversary_hparams=odd)
        with caplog.at_level(logging.WARNING, logger="advgame.training.loop"):
            Run(Trainer(cfg, tmp_path / method))
        warned = {s for s in ("protagonist", "adversary") if f"each {s} phase" in caplog.text}
        assert warned == sides, method
