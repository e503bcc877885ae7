"""The paper's causal tasks (RS-LiftCausal, RS-DoorCausal): features, correlations, the live model.

Each preset is played by its own suggested adversary over a few resets. From the protagonist's
observation we read the causal feature (the cube's side of the table; the door's turn, from the
model) and the spurious one (the cube's colour, the handle's height), and check that their
correlation is the one the preset declares: the paper's ``spurious_type`` (training), the
reversed one, or none (each causal value seen with both spurious values). The live model must
agree (the cube's ``geom_rgba``, the door's ``body_quat``, the latch's ``body_pos``), and the
protagonist's reward is the paper's. No step is simulated: resets and setup moves only.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

import advgame
from advgame.adversaries import ConstantAdversary
from advgame.disruptors import Shift, WorkspaceDisruptor
from advgame.errors import BudgetError, ConfigError
from advgame.scenarios.robosuite_causal import SpuriousCorrelation

AGENT = "workspace_adversary"
EPISODES = 16


def _yaw(quat: np.ndarray) -> float:
    """The z rotation of a ``(w, x, y, z)`` quaternion turning about z only, in (-pi, pi]."""
    return float(2.0 * np.arctan2(quat[3], quat[0]))


def _lift_features(game: advgame.Game) -> tuple[int, int]:
    """(side, colour) of the cube as the protagonist sees it; checks the live model agrees."""
    state = game.observe("protagonist")[game.task.observation_keys["object-state"]]
    x, y = state[0], state[1]  # cube_pos leads object-state, cube_color ends it
    assert abs(x) <= 0.1 + 1e-9 and 0.05 - 1e-9 <= abs(y) <= 0.1 + 1e-9  # the paper's draw
    rgb = state[-3:]
    assert any(np.array_equal(rgb, c) for c in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])), rgb
    sim = game.task.sim
    np.testing.assert_array_equal(sim.model.geom_rgba[sim.geom_id("cube_g0_vis")][:3], rgb)
    return (1 if y > 0 else -1), (1 if rgb[0] == 1.0 else -1)


def _door_features(game: advgame.Game) -> tuple[int, int]:
    """(turn, handle height) of the door; the height as the protagonist sees it."""
    sim = game.task.sim
    turn = _yaw(sim.model.body_quat[sim.body_id("Door_main")]) + np.pi / 2
    assert 0.3 - 1e-9 <= abs(turn) <= 0.35 + 1e-9  # the paper's two yaw intervals
    state = game.observe("protagonist")[game.task.observation_keys["object-state"]]
    height = state[5] - state[2]  # handle_pos z - door_pos z
    latch = sim.model.body_pos[sim.body_id("Door_latch")]
    np.testing.assert_allclose(latch, [-0.175, 0.0, height], atol=1e-9)
    assert height == pytest.approx(0.2) or height == pytest.approx(-0.1), height
    return (1 if turn < 0 else -1), (1 if height > 0 else -1)  # +1: left, high


def _play(sid: str, preset: str) -> list[tuple[int, int]]:
    """(causal, spurious) of `EPISODES` resets, the preset's own adversary choosing them."""
    game = advgame.make(sid, preset=preset, max_episode_steps=2)
    try:
        policy = game.preset.adversaries[AGENT].build(game.agent_info(AGENT))
        policy.reset(seed=1)  # 8 of 16 sides positive (seed 0 draws 13 negative ones)
        read = _lift_features if sid == "RS-LiftCausal" else _door_features
        out = []
        for i in range(EPISODES):
            game.reset(seed=i)
            assert game.next_movers == frozenset({AGENT})
            game.play({AGENT: policy.act(game.observe(AGENT))})
            out.append(read(game))
        return out
    finally:
        game.close()


# (scenario, preset, sign): spurious = sign * causal in every episode; 0: independent
CASES = [
    ("RS-LiftCausal", "spurious-xnr", -1),  # red when y <= 0
    ("RS-LiftCausal", "default", -1),  # the paper's default spurious_type, xnr
    ("RS-LiftCausal", "spurious-xpr", 1),  # red when y > 0: xnr reversed
    ("RS-LiftCausal", "spurious-none", 0),
    ("RS-DoorCausal", "spurious-hhl", 1),  # high handle when the door turns left
    ("RS-DoorCausal", "default", 1),  # hhl
    ("RS-DoorCausal", "spurious-hhr", -1),  # high handle when it turns right: hhl reversed
    ("RS-DoorCausal", "spurious-none", 0),
]


@pytest.mark.parametrize(("sid", "preset", "sign"), CASES, ids=[f"{s}:{p}" for s, p, _ in CASES])
def test_each_preset_plays_its_declared_correlation(sid: str, preset: str, sign: int) -> None:
    pairs = _play(sid, preset)
    for causal in (-1, 1):
        seen = {s for c, s in pairs if c == causal}
        assert seen, f"{preset}: the causal feature never took the value {causal}"
        assert seen == ({sign * causal} if sign else {-1, 1}), (preset, causal, seen)


def test_training_and_test_presets_draw_the_same_causal_features() -> None:
    train, reversed_ = (
        _play("RS-LiftCausal", "spurious-xnr"),
        _play("RS-LiftCausal", "spurious-xpr"),
    )
    assert [c for c, _ in train] == [c for c, _ in reversed_]
    assert [s for _, s in train] == [-s for _, s in reversed_]


@pytest.fixture(scope="module")
def lift() -> Iterator[advgame.Game]:
    game = advgame.make("RS-LiftCausal", preset="adversarial", max_episode_steps=2)
    yield game
    game.close()


def test_any_adversary_drives_the_features_and_reset_restores(lift: advgame.Game) -> None:
    assert dict(lift.preset.adversaries) == {}  # the loop learns this adversary
    sim, geom = lift.task.sim, lift.task.sim.geom_id("cube_g0_vis")
    nominal = sim.model.geom_rgba[geom].copy()
    np.testing.assert_array_equal(nominal, [0.5, 0.5, 0.0, 1.0])
    policy = ConstantAdversary((1.0, -1.0)).build(lift.agent_info(AGENT))
    lift.reset(seed=3)
    lift.play({AGENT: policy.act(None)})
    assert _lift_features(lift) == (1, -1)  # y > 0 and green: a pairing no preset trains on
    lift.reset(seed=3)
    np.testing.assert_array_equal(sim.model.geom_rgba[geom], nominal)
    lift.play({AGENT: np.array([0.0, 0.5], dtype=np.float32)})
    np.testing.assert_allclose(sim.model.geom_rgba[geom], [0.75, 0.25, 0.0, 1.0])


def test_lift_reward_is_the_papers(lift: advgame.Game) -> None:
    lift.reset(seed=0)
    env = lift.task.env
    d = np.linalg.norm(env._get_observations(force_update=True)["gripper_to_cube_pos"])
    assert env.reward() == pytest.approx(1.0 - np.tanh(10.0 * d))  # reaching, no grasp
    qpos = env.sim.model.get_joint_qpos_addr(env.cube.joints[0])[0]
    env.sim.data.qpos[qpos + 2] += 0.1  # lifted 10 cm
    env.sim.forward()
    assert env._check_success() and env.reward() == 1.0


def test_door_opened_is_worth_half() -> None:
    game = advgame.make("RS-DoorCausal", preset="spurious-hhl", max_episode_steps=2)
    try:
        game.reset(seed=0)
        env = game.task.env
        assert not env._check_success() and env.reward() < 0.5
        env.sim.data.qpos[env.hinge_qpos_addr] = 0.35
        env.sim.forward()
        assert env._check_success() and env.reward() == 0.5
    finally:
        game.close()


def test_yaw_turns_a_fixed_body_and_a_free_object_and_is_restored() -> None:
    turn = WorkspaceDisruptor(shifts=[Shift("turn", bodies=["goal"], yaw=0.4)])
    game = advgame.make("Pusher-v5", disruptors=[turn])
    goal = game.task.sim.body_id("goal")
    game.reset(seed=0)
    quat0 = game.task.sim.model.body_quat[goal].copy()
    game.play({AGENT: np.array([0.5], dtype=np.float32)})
    assert _yaw(game.task.sim.model.body_quat[goal]) - _yaw(quat0) == pytest.approx(0.2)
    game.reset(seed=0)
    np.testing.assert_array_equal(game.task.sim.model.body_quat[goal], quat0)
    game.close()
    spin = WorkspaceDisruptor(shifts=[Shift("spin", bodies=["cube_main"], yaw=np.pi / 2)])
    cube = advgame.make("RS-LiftCausal", disruptors=[spin], max_episode_steps=2)
    try:
        cube.reset(seed=0)
        body = cube.task.sim.body_id("cube_main")
        before = _yaw(cube.task.sim.data.xquat[body])
        cube.play({AGENT: np.array([-1.0], dtype=np.float32)})
        after = _yaw(cube.task.sim.data.xquat[body])
        assert np.cos(after - before) == pytest.approx(0.0, abs=1e-9)
        assert np.sin(after - before) == pytest.approx(-1.0)
    finally:
        cube.close()


def test_bad_correlations_and_turns_say_what_is_wrong(lift: advgame.Game) -> None:
    with pytest.raises(ConfigError, match=r"probability in \[0, 1\]"):
        SpuriousCorrelation(agree=1.5)
    with pytest.raises(ConfigError, match="two different dimensions"):
        SpuriousCorrelation(causal=1, spurious=1)
    with pytest.raises(ConfigError, match="dimensions 0 and 3"):
        SpuriousCorrelation(spurious=3).build(lift.agent_info(AGENT))
    with pytest.raises(BudgetError, match="needs at least one body"):
        Shift("t", geoms=["cube_g0_vis"], yaw=0.3)
    with pytest.raises(ConfigError, match="yaw"):
        Shift("t", bodies=["cube_main"], yaw="left")  # type: ignore[arg-type]


@pytest.mark.parametrize("scenario", ["RS-LiftCausal", "RS-DoorCausal"])
def test_the_atla_preset_and_the_horizon_are_the_papers(
    scenario: str,
) -> None:
    from advgame.scenarios.robosuite_causal import ATLA_EPS

    game = advgame.make(scenario, preset="atla", max_episode_steps=2)
    default = advgame.make(scenario, preset="default", max_episode_steps=2)
    obs = [d for d in game.preset.disruptors if d.kind == "observation"]
    assert len(obs) == 1 and obs[0].eps == ATLA_EPS == 0.01 and obs[0].space == "normalized"
    # the workspace correlation is fixed (the training one); the observation adversary is free
    assert game.preset.adversaries == default.preset.adversaries
    assert "observation_adversary" not in game.preset.adversaries
    game.close()
    default.close()
    paper = advgame.make(scenario, preset="default")
    assert paper.task.max_episode_steps == 300  # the paper's horizon (its RSC table)
    paper.close()
