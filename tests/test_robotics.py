"""gymnasium-robotics scenarios: Dict observations disrupted correctly, true rewards, HER.

Robust-Gymnasium's Fetch and Shadow Hand state noise never reaches the observation, and its
Maze scenarios ignore their disruptor input; the tests named ``*_reaches_*`` and
``test_maze_*`` show both fixed here. Conformance of every robotics id runs from the registry
in tests/test_conformance.py (every id, in the default suite).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import advgame
from advgame import ObservationDisruptor
from advgame.core.registry import scenario_spec
from advgame.errors import BudgetError, ConfigError, UnknownNameError
from advgame.scenarios.robotics_list import ENVS, FAMILIES

pytest.importorskip("gymnasium_robotics")

GOAL_EPS = {"observation": 0.02, "achieved_goal": 0.03, "desired_goal": 0.05}
"""A per-key budget distinct per key, so a leak of one key's budget into another shows."""


def _leaf(obs: dict[str, Any], name: str) -> np.ndarray:
    for key in name.split("/"):
        obs = obs[key]
    return np.asarray(obs)


def _episode(game: advgame.Game, seed: int, steps: int, rng_seed: int = 3) -> list[dict]:
    """Play `steps` steps: random protagonist actions and observation-adversary actions in
    [-1.5, 1.5] (some clipped); record what the protagonist saw and the true values."""
    rng, adversary_rng = np.random.default_rng(rng_seed), np.random.default_rng(rng_seed + 1)
    game.reset(seed=seed)
    out: list[dict] = []
    p = "protagonist"
    while game.agents and len(out) < steps:
        record: dict[str, Any] = {"true": game.true_observation(p)}
        if game.move == "sense":
            for a in game.next_movers:
                u = adversary_rng.uniform(-1.5, 1.5, game.action_space(a).shape)
                game.play({a: u})
        record["shown"] = game.observe(p)
        move = game.play({p: rng.uniform(-1, 1, game.action_space(p).shape)})
        assert move.info is not None
        record.update(reward=move.reward, info=move.info)
        out.append(record)
    return out


def test_every_robotics_id_is_registered_with_its_family_and_extra() -> None:
    for family in FAMILIES:
        ids = advgame.list_scenarios(family=family)
        assert set(ids) == {i for i, (f, _) in ENVS.items() if f == family}, family
    for sid, (family, _) in ENVS.items():
        spec = scenario_spec(sid)
        assert (spec.family, spec.extra, spec.requires) == (
            family,
            "robotics",
            ("gymnasium_robotics",),
        )
        names = spec.load_presets()
        assert {"default", "full", "state-gauss-0.1", "action-gauss-0.1"} <= set(names)
        assert ("goals" in names) == (family != "adroit")  # Adroit observes a Box, no goals


@pytest.mark.parametrize(
    "sid", ["FetchPush-v4", "HandReach-v3", "HandManipulateBlock_ContinuousTouchSensors-v1"]
)
def test_observation_attack_reaches_protagonist_within_each_key_budget(sid: str) -> None:
    attacked = advgame.make(sid, disruptors=[ObservationDisruptor(eps=GOAL_EPS)])
    nominal = advgame.make(sid, disruptors=[])
    steps = 6
    seen = _episode(attacked, seed=5, steps=steps)
    true = _episode(nominal, seed=5, steps=steps)
    assert len(seen) == len(true) == steps
    for a, b in zip(seen, true, strict=True):
        assert isinstance(a["shown"], dict) and a["shown"].keys() == b["true"].keys()
        for key, eps in GOAL_EPS.items():
            delta = a["shown"][key] - a["true"][key]
            assert np.abs(delta).max() <= eps + 1e-12, (key, np.abs(delta).max())
            assert np.abs(delta).max() > 0.5 * eps, f"{key}: the attack did not reach it"
            # the simulator is untouched: the attacked game's true state is the nominal one's
            np.testing.assert_array_equal(a["true"][key], b["true"][key])
        assert a["reward"] == b["reward"]  # rewarded against the true goals
        assert a["info"]["is_success"] == b["info"]["is_success"]
        np.testing.assert_array_equal(a["info"]["true_desired_goal"], b["true"]["desired_goal"])


@pytest.mark.parametrize("sid", ["FetchReach-v4", "HandManipulatePen-v1"])
def test_paper_state_noise_reaches_every_key_and_leaves_true_reward(sid: str) -> None:
    game = advgame.make(sid, preset="state-gauss-0.1")
    nominal = advgame.make(sid, disruptors=[])
    for a, b in zip(_episode(game, 2, 4), _episode(nominal, 2, 4), strict=True):
        for key in ("observation", "achieved_goal", "desired_goal"):
            assert not np.array_equal(a["shown"][key], a["true"][key]), key
            np.testing.assert_array_equal(a["true"][key], b["true"][key])
        assert a["reward"] == b["reward"]


def test_adversary_action_is_keys_concatenated_in_the_given_order() -> None:
    game = advgame.make(
        "FetchReach-v4",
        disruptors=[
            ObservationDisruptor(keys=["desired_goal", "observation"], eps=[0.1] * 3 + [0.01] * 10)
        ],
    )
    assert game.action_space("observation_adversary").shape == (13,)
    game.reset(seed=0)
    u = np.linspace(-1, 1, 13)
    game.play({"observation_adversary": u})
    shown, true = game.observe("protagonist"), game.true_observation("protagonist")
    np.testing.assert_allclose(shown["desired_goal"] - true["desired_goal"], 0.1 * u[:3])
    np.testing.assert_allclose(shown["observation"] - true["observation"], 0.01 * u[3:])
    np.testing.assert_array_equal(shown["achieved_goal"], true["achieved_goal"])
    # adversaries observe the true state: every leaf, in the Dict space's (sorted) order
    state = game.state()
    parts = [true[k] for k in ("achieved_goal", "desired_goal", "observation")]
    np.testing.assert_array_equal(state, np.concatenate(parts))
    assert game.state_space.contains(state)


def test_l2_budget_is_per_key() -> None:
    game = advgame.make(
        "FetchReach-v4",
        disruptors=[
            ObservationDisruptor(eps={"desired_goal": 0.05, "achieved_goal": 0.02}, norm="l2")
        ],
    )
    game.reset(seed=0)
    game.play({"observation_adversary": np.full(6, 5.0)})
    shown, true = game.observe("protagonist"), game.true_observation("protagonist")
    for key, eps in (("desired_goal", 0.05), ("achieved_goal", 0.02)):
        assert np.linalg.norm(shown[key] - true[key]) == pytest.approx(eps)


def test_kitchen_nested_goal_keys_keep_their_structure() -> None:
    game = advgame.make(
        "FrankaKitchen-v1",
        disruptors=[ObservationDisruptor(eps={"desired_goal/kettle": 0.2, "observation": 0.01})],
    )
    assert game.action_space("observation_adversary").shape == (7 + 59,)
    game.reset(seed=1)
    game.play({"observation_adversary": np.ones(66)})
    shown, true = game.observe("protagonist"), game.true_observation("protagonist")
    assert (
        isinstance(shown["desired_goal"], dict)
        and shown["desired_goal"].keys() == true["desired_goal"].keys()
    )
    np.testing.assert_allclose(
        shown["desired_goal"]["kettle"] - true["desired_goal"]["kettle"], 0.2
    )
    np.testing.assert_allclose(shown["observation"] - true["observation"], 0.01)
    for task in true["desired_goal"]:
        if task != "kettle":
            np.testing.assert_array_equal(shown["desired_goal"][task], true["desired_goal"][task])
    assert game.observation_space("protagonist").contains(shown)
    move = game.play({"protagonist": np.zeros(9)})
    assert move.info is not None and "is_success" in move.info


def test_maze_observation_and_action_disruptors_change_what_they_should() -> None:
    """Robust-Gymnasium's Maze ignores its disruptor input; here both inputs act."""
    obs_game = advgame.make("PointMaze_UMaze-v3", disruptors=[ObservationDisruptor(eps=0.1)])
    for rec in _episode(obs_game, 0, 5):
        delta = np.concatenate([rec["shown"][k] - rec["true"][k] for k in rec["true"]])
        assert 0 < np.abs(delta).max() <= 0.1 + 1e-12
        assert "is_success" in rec["info"]

    def final_position(u: float) -> np.ndarray:
        game = advgame.make("PointMaze_UMaze-v3", preset="default")
        game.reset(seed=0)
        for _ in range(20):
            if game.move == "sense":
                game.play({"observation_adversary": np.zeros(8)})
            game.play({"protagonist": np.zeros(2), "action_adversary": np.full(2, u)})
        return game.true_observation("protagonist")["achieved_goal"]

    still, pushed = final_position(0.0), final_position(1.0)
    assert np.linalg.norm(pushed - still) > 0.01  # the action adversary moved the ball


def _model_params(game: advgame.Game) -> dict[str, np.ndarray]:
    model = game.task.sim.model
    return {
        "mass": model.body_mass.copy(),
        "inertia": model.body_inertia.copy(),
        "friction": model.geom_friction.copy(),
        "damping": model.dof_damping.copy(),
        "gear": model.actuator_gear.copy(),
        "gravity": model.opt.gravity.copy(),
    }


@pytest.mark.parametrize(
    "sid",
    [
        "PointMaze_UMaze-v3",
        "AntMaze_UMaze-v5",
        "FetchPush-v4",
        "HandReach-v3",
        "AdroitHandHammer-v1",
        "FrankaKitchen-v1",
    ],
)
def test_dynamics_shift_acts_and_is_restored_exactly_on_reset(sid: str) -> None:
    game = advgame.make(sid, preset="full", max_episode_steps=5)
    game.reset(seed=0)
    nominal = _model_params(game)
    kinds = [p.kind for p in game.disruptors["dynamics_adversary"].spec.params]  # type: ignore[attr-defined]
    while game.agents:
        actions = {a: game.action_space(a).sample() for a in game.agents}
        actions["dynamics_adversary"] = np.ones(len(kinds), dtype=np.float32)  # +20 % on all
        game.step(actions)
    shifted = _model_params(game)
    for kind in kinds:  # every adversary input moves the model (none is a dead input)
        assert not np.array_equal(shifted[kind], nominal[kind]), f"{sid}: {kind} unchanged"
    game.reset(seed=1)
    for kind, value in _model_params(game).items():
        np.testing.assert_array_equal(value, nominal[kind], err_msg=f"{sid}: {kind}")


def test_seeded_rollouts_reproduce_with_dict_observations() -> None:
    from advgame.adversaries import RandomAdversary

    def run(seed: int) -> list[float]:
        game = advgame.make("FetchPush-v4", preset="full", max_episode_steps=8, reward_type="dense")
        policies = {
            "protagonist": lambda obs: np.clip(np.append(obs["desired_goal"] - 1.0, 0.0), -1, 1),
            **{a: RandomAdversary() for a in game.adversaries},
        }
        return [r.true_return for r in advgame.rollout(game, policies, seed=seed, episodes=2)]

    first = run(4)
    assert first == run(4) and len(first) == 2
    assert first != run(5)  # dense returns: a different seed is a different episode


def test_dict_observation_errors_name_the_fix() -> None:
    with pytest.raises(UnknownNameError, match="desired_goal"):
        advgame.make("FetchReach-v4", disruptors=[ObservationDisruptor(keys=["desired_gaol"])])
    with pytest.raises(BudgetError, match="'achieved_goal'"):
        advgame.make(
            "FetchReach-v4",
            disruptors=[ObservationDisruptor(keys=["achieved_goal"], eps={"desired_goal": 0.1})],
        )
    with pytest.raises(ConfigError, match="keys="):
        advgame.make("FetchReach-v4", disruptors=[ObservationDisruptor(dims=[0, 1])])
    with pytest.raises(ConfigError, match="Dict observation"):
        advgame.make(
            "AdroitHandDoor-v1", disruptors=[ObservationDisruptor(eps={"observation": 0.1})]
        )
    with pytest.raises(ConfigError, match="bounded=True"):
        ObservationDisruptor(eps={"observation": 0.1}, bounded=False)
    with pytest.raises(BudgetError, match="must be >= 0"):
        ObservationDisruptor(eps={"observation": -0.1})


def test_white_box_attack_on_a_dict_observation_is_a_clear_error() -> None:
    from advgame.adversaries.whitebox import MADAttack
    from advgame.core.episodes import build_policies

    class DictVictim:  # white-box by its methods (the WhiteBox protocol), Dict by its task
        def reset(self, seed: int | None = None) -> None:
            pass

        def act(self, observation: Any) -> np.ndarray:
            return np.zeros(4, dtype=np.float32)

        action_mean = action_std = value = q_value = act

    game = advgame.make(
        "FetchReach-v4", disruptors=[ObservationDisruptor(eps={"desired_goal": 0.01})]
    )
    with pytest.raises(ConfigError, match="do not cover Dict observations"):
        build_policies(game, {"protagonist": DictVictim(), "observation_adversary": MADAttack()})


def _her_view() -> Any:
    from advgame.adversaries import RandomAdversary
    from advgame.core.views import SingleAgentView

    game = advgame.make("FetchReach-v4", preset="goals", max_episode_steps=10)
    return SingleAgentView(game, "protagonist", {"observation_adversary": RandomAdversary()})


def test_her_stores_what_was_seen_and_relabels_with_true_goals(one_torch_thread: None) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from advgame.agents import SACConfig
    from advgame.agents.sb3.her import TrueGoalHerReplayBuffer

    venv = DummyVecEnv([_her_view])
    config = SACConfig(her=True, learning_starts=50, buffer_size=500, batch_size=16, net_arch=(32,))
    model = config.make_model(venv, seed=0, total_steps=200)
    assert type(model.policy).__name__ == "MultiInputPolicy"
    model.learn(200)
    buf = model.replay_buffer
    assert isinstance(buf, TrueGoalHerReplayBuffer) and buf.pos == 200
    view, n = venv.envs[0], buf.pos
    true_next, true_desired = buf.true_achieved[:n, 0], buf.true_desired[:n, 0]
    # the network trains on what the protagonist saw: the goals inside the attack's budget
    seen = buf.next_observations["achieved_goal"][:n, 0] - true_next
    assert 0 < np.abs(seen).max() <= 0.01 + 1e-9
    # the view's compute_reward is the task's, and the stored rewards are the true ones
    task_reward = view.game.task.env.unwrapped.compute_reward(true_next, true_desired, {})
    np.testing.assert_array_equal(view.compute_reward(true_next, true_desired, {}), task_reward)
    np.testing.assert_array_equal(buf.rewards[:n, 0], task_reward)
    # relabelled samples: new goals are true achieved goals of the same episode, later on,
    # shown through the stored attack, and rewarded by the task on true achieved goals
    idx = np.random.default_rng(0).integers(0, n, 64)
    np.random.seed(0)  # noqa: NPY002 - SB3 draws HER's future indices from the global generator
    sample = buf._get_virtual_samples(idx, np.zeros(64, dtype=np.int64))
    attack = buf.observations["desired_goal"][idx, 0] - buf.true_desired[idx, 0]
    goals = sample.observations["desired_goal"].numpy() - attack
    expected = view.compute_reward(buf.true_achieved[idx, 0], goals, {})
    np.testing.assert_allclose(sample.rewards.numpy().ravel(), expected)
    for i, goal in zip(idx, goals, strict=True):
        end = (i // 10 + 1) * 10
        assert any(np.allclose(goal, buf.true_achieved[j, 0]) for j in range(i, end)), i


def test_her_needs_true_goals_in_info_and_a_goal_task() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from advgame.agents import SACConfig
    from advgame.core.views import SingleAgentView

    box = DummyVecEnv([lambda: SingleAgentView(advgame.make("AdroitHandDoor-v1"), "protagonist")])
    with pytest.raises(ConfigError, match="achieved_goal"):
        SACConfig(her=True).make_model(box, seed=0, total_steps=10)
    with pytest.raises(ConfigError, match="her_goal_selection"):
        SACConfig(her=True, her_goal_selection="futur")
    # no Box goals, no compute_reward: SB3 treats any env that has one as a goal env
    kitchen = advgame.make("FrankaKitchen-v1", disruptors=[])
    assert not hasattr(SingleAgentView(kitchen, "protagonist"), "compute_reward")
    with pytest.raises(ConfigError, match="HER needs"):
        kitchen.task.compute_reward({}, {}, {})
    fetch = advgame.make("FetchReach-v4", preset="goals")
    assert not hasattr(
        SingleAgentView(fetch, "observation_adversary", {"protagonist": lambda obs: np.zeros(4)}),
        "compute_reward",
    )


def test_training_loop_runs_sac_her_under_attack(tmp_path: Any, one_torch_thread: None) -> None:
    from advgame.agents.common.checkpoint import SB3Checkpoint
    from advgame.training import train
    from advgame.training.config import TrainConfig

    config = TrainConfig(
        scenario="FetchReach-v4",
        preset="goals",
        protagonist_algo="sac",
        protagonist_hparams={"her": True, "learning_starts": 50, "buffer_size": 500},
        adversary_hparams={"n_steps": 32, "batch_size": 16},
        iterations=1,
        protagonist_steps=100,
        adversary_steps=32,
        normalize=False,
        eval_episodes=1,
    )
    run = train(config, str(tmp_path / "run"), progress=False)
    [zip_path] = list((tmp_path / "run").glob("checkpoints/iter_*/protagonist.zip"))
    game = advgame.make("FetchReach-v4", preset="goals")
    policy = SB3Checkpoint(str(zip_path), "sac").build(game.agent_info("protagonist"))
    obs, _ = game.reset(seed=0)
    assert game.action_space("protagonist").contains(
        policy.act(obs["protagonist"]).astype(np.float32)
    )
    assert run
    with pytest.raises(ConfigError, match="normalize=False"):
        train(
            TrainConfig(**{**config.__dict__, "normalize": True}),
            str(tmp_path / "norm"),
            progress=False,
        )


def test_goal_view_passes_sb3_env_checker_as_a_goal_env() -> None:
    import warnings

    from stable_baselines3.common.env_checker import check_env

    view = _her_view()
    assert view.observation_space is view.game.observation_space("protagonist")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # unbounded observation spaces: a warning, not an error
        check_env(view, warn=True)  # includes SB3's goal-env checks of compute_reward
    obs, info = view.reset(seed=0)
    assert view.observation_space.contains(obs) and "is_success" in info
