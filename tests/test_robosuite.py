"""robosuite scenarios: workspace disturbances, exact restoration, the adversarial arm, training.

Every robosuite scenario also runs through tests/test_conformance.py (short horizons). These
tests check what the registry-driven ones cannot: that each semantic disturbance really moves
the object or door and really changes the colour in the model, and is gone after the next
reset; that dynamics edits are restored exactly; that the adversary arm moves and changes the
door's state (robosuite issue #737 reports second arms ignoring their actions); seeded
reproduction; and a real training iteration of MultiRobustDoor in the loop.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import advgame
from advgame.core.schedule import Schedule
from advgame.disruptors import (
    ArmDisruptor,
    DynamicsDisruptor,
    ObservationDisruptor,
    Param,
    WorkspaceDisruptor,
)
from advgame.errors import ConfigError, UnknownNameError


@pytest.fixture(scope="session")
def warm() -> None:
    """Step robosuite once per test session: its first step compiles numba (~10-16 s)."""
    game = advgame.make("RS-Lift", max_episode_steps=2)
    game.reset(seed=0)
    game.play({a: game.action_space(a).sample() * 0 for a in game.next_movers})
    game.close()


@pytest.fixture
def lift(warm: None) -> Iterator[advgame.Game]:
    game = advgame.make("RS-Lift", preset="lift-shift", max_episode_steps=5)
    yield game
    game.close()


def _id(game: advgame.Game, kind: str, name: str) -> int:
    obj = {"body": mujoco.mjtObj.mjOBJ_BODY, "geom": mujoco.mjtObj.mjOBJ_GEOM}[kind]
    return int(mujoco.mj_name2id(game.task.sim.model, obj, name))


def _setup(game: advgame.Game, agent: str, u: list[float], seed: int = 0) -> dict:
    """Reset, play the setup move with `u`, return the protagonist's first observation."""
    first, _ = game.reset(seed=seed)
    assert game.next_movers == frozenset({agent}) and game.move == "sense"
    game.play({agent: np.asarray(u, dtype=np.float32)})
    assert "protagonist" in game.next_movers  # the protagonist moves next, on the new scene
    return {"before": first["protagonist"], "after": game.observe("protagonist")}


def test_lift_shift_moves_and_recolours_the_cube_then_reset_restores(lift: advgame.Game) -> None:
    sim = lift.task.sim
    body, geom = _id(lift, "body", "cube_main"), _id(lift, "geom", "cube_g0_vis")
    lift.reset(seed=0)
    pos0, rgba0 = sim.data.xpos[body].copy(), sim.model.geom_rgba[geom].copy()
    obs = _setup(lift, "workspace_adversary", [1.0])
    np.testing.assert_allclose(sim.data.xpos[body] - pos0, [0.0, 0.08, 0.0], atol=1e-9)
    np.testing.assert_allclose(sim.model.geom_rgba[geom], [0.0, 0.2, 1.0, 1.0], atol=1e-6)
    cube = lift.task.observation_keys["object-state"].start  # cube_pos leads object-state
    assert obs["after"][cube + 1] - obs["before"][cube + 1] == pytest.approx(0.08)
    _setup(lift, "workspace_adversary", [-0.5])
    np.testing.assert_allclose(
        sim.model.geom_rgba[geom], rgba0 + 0.5 * ([0.0, 0.8, 0.1, 1.0] - rgba0), atol=1e-6
    )
    lift.reset(seed=0)  # the next reset is nominal: same seed, same cube, nominal colour
    np.testing.assert_array_equal(sim.data.xpos[body], pos0)
    np.testing.assert_array_equal(sim.model.geom_rgba[geom], rgba0)


def test_door_shift_moves_door_and_raises_handle_together(warm: None) -> None:
    game = advgame.make("RS-Door", preset="door-shift", max_episode_steps=5)
    sim, env = game.task.sim, game.task.env
    door = _id(game, "body", "Door_main")
    game.reset(seed=1)
    door0, handle0 = sim.model.body_pos[door].copy(), env._handle_xpos.copy()
    _setup(game, "workspace_adversary", [1.0], seed=1)
    np.testing.assert_allclose(sim.model.body_pos[door] - door0, [0.10, 0.0, 0.0], atol=1e-12)
    assert env._handle_xpos[2] - handle0[2] == pytest.approx(0.05, abs=1e-9)
    game.reset(seed=1)
    np.testing.assert_array_equal(sim.model.body_pos[door], door0)
    np.testing.assert_array_equal(env._handle_xpos, handle0)
    game.close()


def test_table_shift_moves_table_and_objects_and_success_height(warm: None) -> None:
    game = advgame.make("RS-Lift", preset="table", max_episode_steps=5)
    sim, env = game.task.sim, game.task.env
    table, cube = _id(game, "body", "table"), _id(game, "body", "cube_main")
    game.reset(seed=2)
    table0, cube0 = sim.model.body_pos[table].copy(), sim.data.xpos[cube].copy()
    height0 = float(env.model.mujoco_arena.table_offset[2])
    _setup(game, "workspace_adversary", [1.0, -1.0, 1.0], seed=2)
    delta = np.array([0.05, -0.05, 0.03])
    np.testing.assert_allclose(sim.model.body_pos[table] - table0, delta, atol=1e-12)
    np.testing.assert_allclose(sim.data.xpos[cube] - cube0, delta, atol=1e-9)
    assert float(env.model.mujoco_arena.table_offset[2]) == pytest.approx(height0 + 0.03)
    game.reset(seed=2)
    np.testing.assert_array_equal(sim.model.body_pos[table], table0)
    assert float(env.model.mujoco_arena.table_offset[2]) == height0
    game.close()


def test_dynamics_edits_are_restored_exactly(warm: None) -> None:
    params = [Param(k, 0.5, 1.5, relative=True) for k in ("mass", "friction", "damping")]
    spec = DynamicsDisruptor(params=params, schedule=Schedule.per_episode())
    game = advgame.make("RS-Door", disruptors=[spec], max_episode_steps=3)
    m = game.task.sim.model
    game.reset(seed=0)
    nominal = [
        m.body_mass.copy(),
        m.body_inertia.copy(),
        m.geom_friction.copy(),
        m.dof_damping.copy(),
    ]
    game.play({"protagonist": np.zeros(7), "dynamics_adversary": np.ones(3, dtype=np.float32)})
    assert not np.array_equal(m.body_mass, nominal[0])  # the shift took effect in the model
    assert not np.array_equal(m.dof_damping, nominal[3])
    game.reset(seed=0)
    for now, before in zip(
        (m.body_mass, m.body_inertia, m.geom_friction, m.dof_damping), nominal, strict=True
    ):
        np.testing.assert_array_equal(now, before)
    game.close()


def _push_handle(game: advgame.Game, arm: bool) -> tuple[float, float]:
    """Drive the adversary arm above the handle and press down (or hold it still)."""
    env = game.task.env
    game.reset(seed=3)
    site = env.robots[1].eef_site_id["right"]
    start = env.sim.data.site_xpos[site].copy()
    while game.agents:
        command = np.zeros(7)
        if arm:
            lift = 0.06 if game.t < 35 else -0.10
            target = env._handle_xpos + np.array([0.0, 0.0, lift])
            command[:3] = np.clip(10.0 * (target - env.sim.data.site_xpos[site]), -1.0, 1.0)
        game.play({"protagonist": np.zeros(7), "arm_adversary": command.astype(np.float32)})
    moved = float(np.linalg.norm(env.sim.data.site_xpos[site] - start))
    return moved, float(env.sim.data.qpos[env.handle_qpos_addr])


def test_adversary_arm_moves_and_turns_the_door_handle(warm: None) -> None:
    game = advgame.make("RS-MultiRobustDoor", max_episode_steps=60)
    assert game.adversaries == ("arm_adversary",)
    assert game.action_space("arm_adversary").shape == (7,)  # its controller's action size
    still_moved, still_handle = _push_handle(game, arm=False)
    moved, handle = _push_handle(game, arm=True)
    assert still_moved < 1e-6 and abs(still_handle) < 0.05  # the no-op arm holds still
    assert moved > 0.15  # the second arm follows its actions (robosuite issue #737)
    assert handle - still_handle > 0.5  # and turns the door's handle (radians)
    game.close()


def test_arm_budget_scales_the_command_and_needs_an_external_robot(warm: None) -> None:
    game = advgame.make("RS-MultiRobustDoor", disruptors=[ArmDisruptor(scale=0.25)])
    game.reset(seed=0)
    game.play({"protagonist": np.zeros(7), "arm_adversary": np.full(7, 3.0, dtype=np.float32)})
    np.testing.assert_allclose(game.task.external_actions[1], 0.25)  # clipped to 1, scaled
    with pytest.raises(ConfigError, match="no external robot"):
        advgame.make("RS-Lift", disruptors=[ArmDisruptor()])
    game.close()


def test_rarl_training_fraction_scales_the_arm_budget() -> None:
    from advgame.training.trainer import scaled

    assert scaled(ArmDisruptor(scale=0.8), 0.5).scale == pytest.approx(0.4)


def test_observation_keys_target_only_object_state(warm: None) -> None:
    spec = ObservationDisruptor(eps=0.5, keys=["object-state"])
    game = advgame.make("RS-Door", disruptors=[spec], max_episode_steps=3)
    part = game.task.observation_keys["object-state"]
    assert game.action_space("observation_adversary").shape == (part.stop - part.start,)
    first, _ = game.reset(seed=0)
    game.play({"observation_adversary": np.ones(part.stop - part.start, dtype=np.float32)})
    shown = game.observe("protagonist")
    np.testing.assert_array_equal(shown[: part.start], first["protagonist"][: part.start])
    np.testing.assert_allclose(shown[part] - first["protagonist"][part], 0.5)
    with pytest.raises(UnknownNameError, match="object-state"):
        advgame.make("RS-Door", disruptors=[ObservationDisruptor(keys=["object_state"])])
    game.close()


def test_seeded_reproduction_and_seed_matters(warm: None) -> None:
    def first_cube(seed: int) -> np.ndarray:
        game = advgame.make("RS-Lift", preset="table", max_episode_steps=3)
        obs, _ = game.reset(seed=seed)
        game.close()
        return obs["protagonist"][game.task.observation_keys["object-state"]]

    np.testing.assert_array_equal(first_cube(5), first_cube(5))
    assert not np.array_equal(first_cube(5), first_cube(6))


def test_unknown_robosuite_env_suggests_the_name(warm: None) -> None:
    from advgame.scenarios.robosuite_task import RobosuiteTask

    with pytest.raises(UnknownNameError, match='Did you mean "Lift"'):
        RobosuiteTask("Lfit")
    with pytest.raises(UnknownNameError, match='Did you mean "Panda"'):
        RobosuiteTask("Lift", robots="Pnda")


def test_multidoor_trains_in_the_loop_and_resumes(tmp_path: Path, one_torch_thread: None) -> None:
    from advgame.training import TrainConfig, resume, train

    config = TrainConfig(
        scenario="RS-MultiRobustDoor",
        preset="default",
        iterations=1,
        protagonist_steps=64,
        adversary_steps=64,
        protagonist_hparams={"n_steps": 64, "batch_size": 32},
        adversary_hparams={"n_steps": 64, "batch_size": 32},
        eval_episodes=0,
    )
    run = train(config, tmp_path / "run", progress=False)
    last = run / "checkpoints" / "iter_0001"
    assert (last / "protagonist.zip").exists() and (last / "arm_adversary.zip").exists()
    members = json.loads((run / "population.json").read_text())
    learned = [m for m in members if m["agent"] == "arm_adversary" and m["learned"]]
    assert learned and learned[-1]["spec"]["type"].endswith("SB3Checkpoint")
    saved = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**saved, "iterations": 2}))  # one more
    resume(run, progress=False)
    assert (run / "checkpoints" / "iter_0002" / "arm_adversary.zip").exists()


CAMERA = """
import numpy as np, advgame
game = advgame.make("RS-Lift", camera_obs=True, camera_heights=16, camera_widths=16)
part = game.task.observation_keys["agentview_image"]
obs, _ = game.reset(seed=0)
image = obs["protagonist"][part]
assert part.stop - part.start == 16 * 16 * 3 and np.ptp(image) > 10, (part, np.ptp(image))
print("ok")
"""


def test_image_observations_are_an_option() -> None:
    """``camera_obs=True`` adds the flattened ``agentview`` image (off-screen EGL rendering)."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "MUJOCO_GL": "egl"}  # read when mujoco starts: a fresh process
    done = subprocess.run(
        [sys.executable, "-c", CAMERA], env=env, capture_output=True, text=True, timeout=300
    )
    if "ok" not in done.stdout and ("EGL" in done.stderr or "glGetError" in done.stderr):
        pytest.skip(f"no off-screen EGL context here: {done.stderr.strip().splitlines()[-1]}")
    assert done.returncode == 0 and "ok" in done.stdout, done.stderr[-2000:]


# -- properties of the two new disruptors (one game each, hypothesis over the action) ---------
FEW = settings(max_examples=12, deadline=None)
UNITS = hnp.arrays(np.float32, 4, elements=st.floats(-3.0, 3.0, width=32))


@pytest.fixture(scope="module")
def workspace_game(warm: None) -> Iterator[advgame.Game]:
    from advgame.scenarios.robosuite import lift_shift, table_shift

    shifts = (*table_shift("Lift").shifts, *lift_shift().shifts)
    game = advgame.make(
        "RS-Lift", disruptors=[WorkspaceDisruptor(shifts=shifts)], max_episode_steps=3
    )
    yield game
    game.close()


@FEW
@given(u=UNITS)
def test_workspace_within_budget_identity_at_zero_restored(
    workspace_game: advgame.Game, u: np.ndarray
) -> None:
    game, sim = workspace_game, workspace_game.task.sim
    table, cube = _id(game, "body", "table"), _id(game, "body", "cube_main")
    geom = _id(game, "geom", "cube_g0_vis")
    game.reset(seed=0)
    model0 = (sim.model.body_pos.copy(), sim.model.geom_rgba.copy())
    cube0 = sim.data.xpos[cube].copy()
    move = game.play({"workspace_adversary": u})
    c = np.clip(u.astype(np.float64), -1.0, 1.0)
    assert move.clipped["workspace_adversary"] == int(np.count_nonzero(np.abs(u) > 1.0))
    shift = sim.model.body_pos[table] - model0[0][table]
    np.testing.assert_allclose(shift, c[:3] * [0.05, 0.05, 0.03], atol=1e-9)  # in the budget
    np.testing.assert_allclose(
        sim.data.xpos[cube] - cube0, shift + np.array([0.0, 0.08 * c[3], 0.0]), atol=1e-9
    )
    rgba = sim.model.geom_rgba[geom]
    assert np.all((rgba >= 0.0) & (rgba <= 1.0))
    if not np.any(c):  # the zero action is the identity
        np.testing.assert_array_equal(sim.model.body_pos, model0[0])
    game.reset(seed=0)
    np.testing.assert_array_equal(sim.model.body_pos, model0[0])
    np.testing.assert_array_equal(sim.model.geom_rgba, model0[1])


@pytest.fixture(scope="module")
def arm_game(warm: None) -> Iterator[advgame.Game]:
    game = advgame.make("RS-MultiRobustDoor", disruptors=[ArmDisruptor(robot=1, scale=0.5)])
    yield game
    game.close()


@FEW
@given(u=hnp.arrays(np.float32, 7, elements=st.floats(-3.0, 3.0, width=32)))
def test_arm_command_stays_in_its_budget(arm_game: advgame.Game, u: np.ndarray) -> None:
    game = arm_game
    game.reset(seed=0)
    game.play({"protagonist": np.zeros(7), "arm_adversary": u})
    command = game.task.external_actions[1]
    np.testing.assert_allclose(command, 0.5 * np.clip(u, -1.0, 1.0), atol=1e-7)
    assert np.all(np.abs(command) <= 0.5)
    game.reset(seed=0)
    assert not np.any(game.task.external_actions[1])  # no command leaks into the next episode


def test_advgame_list_shows_the_robosuite_family(capsys: pytest.CaptureFixture[str]) -> None:
    from advgame.cli import main

    assert main(["list", "--family", "robosuite", "--presets", "RS-MultiRobustDoor"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].split()[:2] == ["RS-MultiRobustDoor", "robosuite"]
    assert "adversarial second arm" in out
    assert main(["list", "--family", "robosuite"]) == 0
    ids = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert ids == advgame.list_scenarios("robosuite") and len(ids) == 14  # 12 + 2 causal


def _hold(obs: np.ndarray) -> np.ndarray:
    """A stand-in protagonist: the zero (hold) command."""
    return np.zeros(7)


def test_payoff_table_of_the_arm_adversary(warm: None) -> None:
    from advgame.adversaries import ConstantAdversary
    from advgame.evaluation import EvalJob, evaluate

    common = {
        "scenario": "RS-MultiRobustDoor",
        "make_kwargs": {"preset": "default", "max_episode_steps": 10},
        "protagonist": "hold",
        "protagonist_spec": _hold,
        "seeds": (0,),
    }
    push = ConstantAdversary([1.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    jobs = [
        EvalJob(**common, adversary="nominal"),
        EvalJob(**common, adversary="push", adversary_specs={"arm_adversary": push}),
    ]
    table = evaluate(jobs, workers=1, progress=False)
    rows, columns, means = table.matrix()
    assert list(rows) == ["hold"] and set(columns) == {"nominal", "push"}
    assert np.all(np.isfinite(means))
    [metrics] = table.metrics()
    assert metrics["protagonist"] == "hold" and np.isfinite(metrics["worst"])


def test_workspace_adversary_learns_one_decision_per_episode(
    warm: None, one_torch_thread: None
) -> None:
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_checker import check_env

    from advgame.core.views import SingleAgentView

    game = advgame.make("RS-Lift", preset="lift-shift", max_episode_steps=3)
    view = SingleAgentView(game, "workspace_adversary", {"protagonist": _hold})
    check_env(view, warn=False)
    view.reset(seed=0)
    _, reward, terminated, truncated, _ = view.step(np.array([1.0], dtype=np.float32))
    assert truncated and not terminated  # one decision per episode: the whole episode inside
    assert np.isfinite(reward) and reward < 0.0  # minus the protagonist's (positive) return
    model = PPO("MlpPolicy", view, n_steps=8, batch_size=8, n_epochs=1, device="cpu", seed=0)
    model.learn(16)  # a learned workspace adversary: 16 episodes, 16 decisions
    assert model.num_timesteps == 16
