"""robosuite robots with their action size kept (`advgame.scenarios.robosuite_lean`): same games."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import advgame


def _robots(game: advgame.Game) -> list:
    return list(game.task.env.robots)


def _play(game: advgame.Game, moves: int, seed: int) -> list:
    """Every move's observations, rewards and ends under actions drawn from `seed`."""
    rng = np.random.default_rng(seed)
    game.reset(seed=seed)
    out = []
    for _ in range(moves):
        acts = {
            a: rng.uniform(-1, 1, game.action_space(a).shape).astype(np.float32)
            for a in sorted(game.next_movers)
        }
        m = game.play(acts)
        shown = {a: np.array(game.observe(a), copy=True) for a in game.possible_agents}
        out.append((m.rewards, m.costs, m.terminated, m.truncated, shown))
        if not game.agents:
            game.reset()
    return out


@pytest.mark.parametrize(
    ("scenario", "preset", "arms"),
    [("RS-DoorCausal", "spurious-hhl", 1), ("RS-MultiRobustDoor", "default", 2)],
)
def test_lean_robots_play_the_games_of_robosuites_own_bit_for_bit(
    scenario: str, preset: str, arms: int
) -> None:
    from robosuite.robots.fixed_base_robot import FixedBaseRobot

    from advgame.scenarios.robosuite_lean import LeanFixedBaseRobot

    lean = advgame.make(scenario, preset=preset, max_episode_steps=12)
    plain = advgame.make(scenario, preset=preset, max_episode_steps=12)
    try:
        assert [type(r) for r in _robots(lean)] == [LeanFixedBaseRobot] * arms
        for robot in _robots(plain):
            robot.__class__ = FixedBaseRobot  # robosuite's own, property and all
        for robot in _robots(lean):
            assert robot.action_dim == FixedBaseRobot.action_dim.fget(robot) > 0
        a, b = _play(lean, 30, seed=3), _play(plain, 30, seed=3)
        assert len(a) == len(b)
        for (ra, ca, ta, ua, sa), (rb, cb, tb, ub, sb) in zip(a, b, strict=True):
            assert (ra, ca, ta, ua) == (rb, cb, tb, ub)
            for agent in sa:
                np.testing.assert_array_equal(sa[agent], sb[agent], err_msg=agent)
    finally:
        lean.close()
        plain.close()


def test_a_wrong_action_is_still_refused_and_a_new_controller_is_measured_again() -> None:
    from robosuite.robots.fixed_base_robot import FixedBaseRobot

    from advgame.scenarios.robosuite_lean import LeanFixedBaseRobot, lean_robots

    game = advgame.make("RS-Lift", max_episode_steps=3)
    try:
        game.reset(seed=0)
        (robot,) = _robots(game)
        size = robot.action_dim
        with pytest.raises(AssertionError, match="invalid action dimension"):
            robot.control(np.zeros(size + 1), policy_step=True)  # robosuite's own check stands
        kept = robot.__dict__["_lean_action_dim"]
        robot._load_controller()  # a new composite controller object: the size is read again
        assert robot.action_dim == FixedBaseRobot.action_dim.fget(robot) == size
        assert robot.__dict__["_lean_action_dim"][0] is not kept[0]
        # pickled by reference (a module-level class), as robosuite's own is
        assert pickle.loads(pickle.dumps(LeanFixedBaseRobot)) is LeanFixedBaseRobot
        assert lean_robots(game.task.env) == 0  # already lean: nothing to swap
    finally:
        game.close()
