"""`advgame.core.views.SingleAgentView`: every side of a game as a checked, reproducible env."""

from __future__ import annotations

import pickle
import re
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

import advgame
from advgame import adversaries as adv
from advgame.core.policy import ConstantPolicy
from advgame.core.schedule import Schedule
from advgame.core.views import SingleAgentView, view_factory
from advgame.disruptors import ActionDisruptor, ObservationDisruptor, RewardDisruptor
from advgame.errors import ConfigError

# Ant episodes are cut short: a per-episode dynamics adversary's single view step plays the
# whole episode, and 1000 Ant steps per view step would make the checkers slow.
ANT_STEPS = 100


def hopper_controller(obs: np.ndarray) -> np.ndarray:
    """A frozen, deterministic Hopper protagonist (plain callable obs -> action)."""
    return np.tanh(np.asarray(obs[2:5], dtype=np.float64) - 0.1).astype(np.float32)


def zero_policy(game: advgame.Game, agent: str = "protagonist") -> ConstantPolicy:
    space = game.action_space(agent)
    return ConstantPolicy(np.zeros(space.shape, dtype=space.dtype))


def gaussian_everyone(game: advgame.Game, std: float = 0.05) -> dict[str, Any]:
    return {a: adv.GaussianAdversary(std=std) for a in game.adversaries}


# -- the views under test --------------------------------------------------------------------
def protagonist_hopper() -> SingleAgentView:
    game = advgame.make("Hopper-v5", preset="default")
    return SingleAgentView(game, "protagonist", gaussian_everyone(game))


def protagonist_cheetah_full() -> SingleAgentView:
    # every disruptor kind embedded at once: observation (sense), reward, action, a per-episode
    # dynamics shift and forces
    game = advgame.make("HalfCheetah-v5", preset="full")
    policies: dict[str, Any] = gaussian_everyone(game)
    policies["dynamics_adversary"] = adv.UniformAdversary(0.8, 1.2)
    return SingleAgentView(game, "protagonist", policies)


def observation_adversary() -> SingleAgentView:
    game = advgame.make("Hopper-v5", preset="default")
    assert game.disruptors["observation_adversary"].timing == "sense"
    return SingleAgentView(game, "observation_adversary", {"protagonist": hopper_controller})


def action_adversary() -> SingleAgentView:
    game = advgame.make("Hopper-v5", preset="default")
    return SingleAgentView(game, "action_adversary", {"protagonist": zero_policy(game)})


def dynamics_adversary() -> SingleAgentView:
    game = advgame.make("Ant-v5", preset="shift-uniform", max_episode_steps=ANT_STEPS)
    assert game.disruptors["dynamics_adversary"].schedule.once_per_episode
    return SingleAgentView(game, "dynamics_adversary", {"protagonist": zero_policy(game)})


def force_adversary() -> SingleAgentView:
    game = advgame.make("Hopper-v5", preset="rarl")
    return SingleAgentView(game, "force_adversary", {"protagonist": hopper_controller})


VIEWS: dict[str, Callable[[], SingleAgentView]] = {
    "protagonist-hopper": protagonist_hopper,
    "protagonist-cheetah-full": protagonist_cheetah_full,
    "observation-adversary": observation_adversary,
    "action-adversary": action_adversary,
    "force-adversary": force_adversary,
    "dynamics-adversary": dynamics_adversary,
}

# Warnings the checkers may raise that are acceptable: MuJoCo observations are physically
# unbounded, so the task's own space is Box(-inf, inf, float64) and the view (rightly) forwards
# it unchanged; Gymnasium's checker flags the infinite bounds (the bare Hopper-v5 gets the same
# warnings). SB3's checker may recommend a symmetric, normalized float32 Box action space: a
# recommendation, not an incompatibility (SB3 casts). Every other warning -- an observation
# outside its space, a reset that ignores its seed, non-deterministic steps -- is a view defect
# and fails the test.
ACCEPTABLE_WARNINGS = (
    re.compile(r"A Box observation space (minimum|maximum) value is -?infinity"),
    re.compile(r"We recommend you to use a symmetric and normalized Box action space"),
    re.compile(r"Your action space has dtype float64, we recommend using np\.float32"),
)


def _run_checker(checker: Callable[[], None]) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        checker()
    return [str(w.message) for w in caught]


def _assert_only_acceptable(messages: list[str]) -> None:
    bad = [m for m in messages if not any(p.search(m) for p in ACCEPTABLE_WARNINGS)]
    assert not bad, f"unexpected checker warnings: {bad}"


@pytest.mark.parametrize("kind", list(VIEWS))
def test_view_spaces_are_the_games(kind: str) -> None:
    view = VIEWS[kind]()
    game = view.game
    assert view.observation_space is game.observation_space(view.agent)
    assert view.action_space is game.action_space(view.agent)
    obs, _ = view.reset(seed=0)
    assert view.observation_space.contains(obs)
    if view.agent in game.adversaries:
        # adversaries observe the true state
        np.testing.assert_array_equal(obs, game.state())
    view.close()


# -- reward semantics ------------------------------------------------------------------------
def _referee(
    game: advgame.Game,
    learner: str,
    protagonist: Callable[[Any], Any],
    actions: list[np.ndarray],
    seed: int,
) -> tuple[list[float], list[int]]:
    """Play `game` move by move without the view: the learner's i-th action on its i-th decision.

    Every other adversary plays its no-op. Returns, per decision, the sum of the learner's reward
    from `Game.step` until its next decision (or the episode end), and the act moves it covered.
    """
    noop = {a: game.agent_info(a).noop_action for a in game.adversaries}
    obs, _ = game.reset(seed=seed)
    sums: list[float] = []
    moves: list[int] = []
    pending = list(actions)
    while game.agents:
        movers = game.next_movers
        acts: dict[str, Any] = dict(noop)
        acts["protagonist"] = (
            protagonist(obs["protagonist"])
            if "protagonist" in movers
            else np.zeros(game.action_space("protagonist").shape, np.float32)
        )
        if learner in movers:
            if not pending:
                break
            acts[learner] = pending.pop(0)
            sums.append(0.0)
            moves.append(0)
        t = game.t
        obs, rewards, _, _, _ = game.step(acts)
        if sums:
            sums[-1] += float(rewards[learner])
            moves[-1] += game.t - t
    return sums, moves


ADVERSARY_GAMES: dict[str, tuple[Callable[[], advgame.Game], Callable[[Any], Any], int]] = {
    # learner -> (game, frozen protagonist, view steps to play)
    "observation_adversary": (  # sense timing, acting every 3rd step: one decision = 3 steps
        lambda: advgame.make(
            "Hopper-v5",
            disruptors=[
                ObservationDisruptor(eps=0.1, schedule=Schedule.every_n(3)),
                ActionDisruptor(eps=0.1),
            ],
        ),
        hopper_controller,
        5,
    ),
    "action_adversary": (
        lambda: advgame.make("Hopper-v5", preset="default"),
        hopper_controller,
        15,
    ),
    "force_adversary": (lambda: advgame.make("Hopper-v5", preset="rarl"), hopper_controller, 15),
    "dynamics_adversary": (  # one decision per episode: the view step covers the whole episode
        lambda: advgame.make("Ant-v5", preset="shift-uniform", max_episode_steps=ANT_STEPS),
        lambda obs: np.zeros(8, np.float32),
        1,
    ),
}


@pytest.mark.parametrize("learner", list(ADVERSARY_GAMES))
def test_adversary_view_reward_is_minus_the_true_payoff_over_the_covered_moves(
    learner: str,
) -> None:
    make_game, protagonist, n = ADVERSARY_GAMES[learner]
    view = SingleAgentView(make_game(), learner, {"protagonist": protagonist})
    rng = np.random.default_rng(1)
    actions = [rng.uniform(-1, 1, view.action_space.shape).astype(np.float32) for _ in range(n)]
    view.reset(seed=11)
    rewards, covered = [], []
    for a in actions:
        t = view.game.t
        _, reward, terminated, truncated, info = view.step(a)
        covered.append(view.game.t - t)
        rewards.append(reward)
        assert isinstance(reward, float)
        assert reward == pytest.approx(-info["payoff"], rel=1e-12, abs=1e-12)
        assert info["payoff"] == pytest.approx(
            info["true_reward"] - view.game.cost_weight * info["true_cost"], rel=1e-12, abs=1e-12
        )
        if terminated or truncated:
            break
    assert len(rewards) == n, "the episode ended before the planned decisions were played"
    assert any(abs(r) > 1e-6 for r in rewards)
    # an independent referee playing the same game move by move agrees step for step
    ref_sums, ref_moves = _referee(make_game(), learner, protagonist, actions, seed=11)
    assert covered == ref_moves
    np.testing.assert_allclose(rewards, ref_sums, rtol=1e-10, atol=1e-10)
    if learner == "observation_adversary":
        assert covered == [3] * n
        assert view.game.move == "sense" and view.game.next_movers == {learner}
    if learner == "dynamics_adversary":
        assert covered == [ANT_STEPS] and not view.game.agents
    view.close()


def test_protagonist_view_reward_is_the_observed_reward() -> None:
    # a reward adversary that adds +0.3 to the observed reward on even steps (its schedule skips
    # odd ones); the adversaries are paid on the true reward, the protagonist sees the observed
    game = advgame.make(
        "Hopper-v5",
        disruptors=[
            ObservationDisruptor(eps=0.1),
            RewardDisruptor(eps=0.5, schedule=Schedule.every_n(2)),
        ],
    )
    view = SingleAgentView(
        game,
        "protagonist",
        {
            "observation_adversary": adv.GaussianAdversary(std=0.05),
            "reward_adversary": adv.ConstantAdversary(0.3),
        },
    )
    obs, _ = view.reset(seed=5)
    shifts = []
    for step in range(12):
        t = game.t
        obs, reward, terminated, truncated, info = view.step(hopper_controller(obs))
        assert game.t == t + 1 == step + 1  # one protagonist decision = one protagonist step
        shifts.append(reward - info["true_reward"])
        assert info["payoff"] == pytest.approx(info["true_reward"], abs=1e-12)
        assert not (terminated or truncated)
    np.testing.assert_allclose(shifts, [0.3, 0.0] * 6, atol=1e-6)


def test_protagonist_view_shows_the_perturbed_state_within_budget() -> None:
    view = protagonist_hopper()
    obs, _ = view.reset(seed=3)
    for _ in range(10):
        delta = obs - view.game.state()
        assert np.all(np.abs(delta) <= 0.1 + 1e-9)
        assert np.any(delta != 0.0)  # the embedded Gaussian adversary did perturb s_t
        obs, _, terminated, truncated, _ = view.step(hopper_controller(obs))
        assert not (terminated or truncated)
    view.close()


# -- reproducibility -------------------------------------------------------------------------
def _trajectory(view: SingleAgentView, seed: int, actions: list[np.ndarray]) -> list[np.ndarray]:
    obs, _ = view.reset(seed=seed)
    out = [obs.copy()]
    for a in actions:
        obs, reward, terminated, truncated, _ = view.step(a)
        out.append(np.append(obs, reward))
        if terminated or truncated:
            obs, _ = view.reset()
            out.append(obs.copy())
    return out


@pytest.mark.parametrize(
    "kind", ["protagonist-hopper", "protagonist-cheetah-full", "observation-adversary"]
)
def test_same_seed_same_actions_give_identical_observations(kind: str) -> None:
    a, b = VIEWS[kind](), VIEWS[kind]()
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-1, 1, a.action_space.shape).astype(np.float32) for _ in range(40)]
    first = _trajectory(a, 123, actions)
    second = _trajectory(b, 123, actions)
    assert len(first) == len(second)
    for x, y in zip(first, second, strict=True):
        np.testing.assert_array_equal(x, y)
    # the same view replays its trajectory when reset with the seed again (embedded policies
    # are reseeded too) ...
    again = _trajectory(a, 123, actions)
    for x, y in zip(first, again, strict=True):
        np.testing.assert_array_equal(x, y)
    # ... and another seed gives another trajectory
    other = _trajectory(b, 124, actions)
    assert not np.array_equal(first[0], other[0])
    a.close()
    b.close()


# -- configuration errors --------------------------------------------------------------------
def test_adversary_view_without_a_protagonist_policy_is_a_config_error() -> None:
    game = advgame.make("Hopper-v5", preset="default")
    with pytest.raises(ConfigError, match="protagonist"):
        SingleAgentView(game, "observation_adversary")
    with pytest.raises(ConfigError, match="protagonist"):
        SingleAgentView(game, "action_adversary", {"observation_adversary": adv.ZeroAdversary()})


def test_view_of_an_adversary_that_never_acts_in_the_phase_is_a_config_error() -> None:
    # the post-training preset: the observation adversary acts at evaluation only
    game = advgame.make("Hopper-v5", preset="state-gauss-0.1-post")
    assert game.phase == "train"
    with pytest.raises(ConfigError, match="never acts"):
        SingleAgentView(game, "observation_adversary", {"protagonist": hopper_controller})
    # the same adversary in the eval phase is a valid learner
    game = advgame.make("Hopper-v5", preset="state-gauss-0.1-post", phase="eval")
    view = SingleAgentView(game, "observation_adversary", {"protagonist": hopper_controller})
    obs, _ = view.reset(seed=0)
    assert view.observation_space.contains(obs)


# -- vectorized, in workers ------------------------------------------------------------------
def _play(venv: Any, seed: int, actions: list[np.ndarray]) -> list[np.ndarray]:
    venv.seed(seed)
    out = [venv.reset()]
    for a in actions:
        obs, rewards, dones, _ = venv.step(a)
        out.extend([obs, rewards, dones.astype(np.float64)])
    venv.close()
    return out


@pytest.mark.parametrize(
    ("agent", "policies", "start_method"),
    [
        (
            "protagonist",
            {
                "observation_adversary": adv.GaussianAdversary(std=0.05),
                "action_adversary": adv.GaussianAdversary(std=0.05),
            },
            "forkserver",
        ),
        (
            "observation_adversary",
            {
                "protagonist": ConstantPolicy(np.full(3, 0.2, np.float32)),
                "action_adversary": adv.UniformAdversary(-0.1, 0.1),
            },
            "spawn",
        ),
    ],
    ids=["protagonist-forkserver", "observation-adversary-spawn"],
)
def test_view_factory_in_subproc_and_dummy_vec_envs(
    agent: str, policies: dict, start_method: str
) -> None:
    factory = view_factory("Hopper-v5", agent, policies, preset="default")
    clone = pickle.loads(pickle.dumps(factory))  # what SubprocVecEnv ships to its workers
    probe = clone()
    assert isinstance(probe, SingleAgentView) and probe.agent == agent
    space = probe.action_space
    probe.close()
    rng = np.random.default_rng(2)
    actions = [rng.uniform(-1, 1, (2, *space.shape)).astype(np.float32) for _ in range(60)]
    dummy = DummyVecEnv([factory, factory])
    subproc = SubprocVecEnv([factory, factory], start_method=start_method)
    assert subproc.num_envs == 2
    assert subproc.observation_space == dummy.observation_space
    assert subproc.action_space == dummy.action_space == space
    in_process = _play(dummy, 9, actions)
    in_workers = _play(subproc, 9, actions)
    assert in_process[0].shape == (2, *probe.observation_space.shape)
    for x, y in zip(in_process, in_workers, strict=True):
        if x.dtype == np.float32 and y.dtype == np.float64:
            # rewards: DummyVecEnv buffers them as float32, SubprocVecEnv stacks the floats
            np.testing.assert_array_equal(x, y.astype(np.float32))
        else:
            np.testing.assert_array_equal(x, y)
    # the two workers were seeded differently, so their games differ
    assert not np.array_equal(in_workers[0][0], in_workers[0][1])


# -- the environment checkers -------------------------------------------------------------
@pytest.mark.parametrize("kind", list(VIEWS))
def test_view_passes_sb3_env_checker(kind: str) -> None:
    view = VIEWS[kind]()
    try:
        _assert_only_acceptable(_run_checker(lambda: sb3_check_env(view, warn=True)))
    finally:
        view.close()


@pytest.mark.parametrize("kind", list(VIEWS))
def test_view_passes_gymnasium_env_checker(kind: str) -> None:
    view = VIEWS[kind]()
    try:
        _assert_only_acceptable(_run_checker(lambda: gym_check_env(view, skip_render_check=True)))
    finally:
        view.close()
