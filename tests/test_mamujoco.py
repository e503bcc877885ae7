"""MaMuJoCo scenarios: conformance, per-agent isolation, partial attacks, team payoffs, the shared model.

Every case comes from the registration table (`advgame.scenarios.mamujoco_list`): each working
factorization x each preset through PettingZoo's `parallel_api_test` and `parallel_seed_test`
(warnings as errors), and each failing one must still fail with the error the table records.
Real MuJoCo throughout.
"""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from collections import Counter
from typing import Any

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo.test import parallel_api_test, parallel_seed_test

import advgame
from advgame.core.registry import list_scenarios, scenario_spec
from advgame.errors import UnknownScenarioError
from advgame.scenarios.mamujoco import FIRST_AGENT, FORCES, MaMuJoCoTask
from advgame.scenarios.mamujoco_list import (
    BROKEN,
    FAMILY,
    UNAVAILABLE,
    VARIANTS,
    register_all,
    working,
)

REGISTERED = register_all()  # idempotent: a no-op once advgame.scenarios registers them itself
CASES = [
    pytest.param(sid, name, id=f"{sid}:{name}")
    for sid in REGISTERED
    for name in scenario_spec(sid).load_presets()
]
FAILING = {**BROKEN, **UNAVAILABLE}
CYCLES = 20
"""Moves per episode in PettingZoo's tests (two episodes per API test)."""


def _assert_same(a: Any, b: Any, where: str) -> None:
    """Exact, recursive equality (dicts, sequences, arrays with dtype, scalars with type)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), f"{where}: {a.keys()} != {b}"
        for k in a:
            _assert_same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert np.asarray(a).dtype == np.asarray(b).dtype, f"{where}: dtypes differ"
        assert np.array_equal(a, b), f"{where}: {a} != {b}"
    else:
        assert type(a) is type(b) and a == b, f"{where}: {a!r} != {b!r}"


# -- the table and the registry ----------------------------------------------------------------
def test_registry_holds_exactly_the_working_variants() -> None:
    assert sorted(REGISTERED) == list_scenarios(family=FAMILY) == sorted(working())
    assert len(REGISTERED) == len(VARIANTS) - len(FAILING)
    assert set(FAILING) <= set(VARIANTS), "every failing row must be a row of the table"
    for sid, v in VARIANTS.items():
        assert sid == f"MA-{v.scenario}-{v.agent_conf}"
    for sid in FAILING:
        with pytest.raises(UnknownScenarioError, match="No scenario"):
            advgame.make(sid)
    assert register_all() == REGISTERED  # a second call changes nothing


@pytest.mark.parametrize("sid", sorted(FAILING))
def test_failing_variants_still_fail_with_the_recorded_error(sid: str) -> None:
    v = VARIANTS[sid]
    try:
        task = MaMuJoCoTask(v.scenario, v.agent_conf)
        task.reset(seed=0)
        task.step({a: np.zeros(s.shape, s.dtype) for a, s in task.action_spaces.items()})
    except Exception as exc:  # the upstream error, whatever its type
        assert f"{type(exc).__name__}: {exc}" == FAILING[sid]
    else:
        pytest.fail(
            f"{sid} now builds and steps with the installed gymnasium-robotics/MuJoCo: remove it "
            "from BROKEN/UNAVAILABLE in advgame/scenarios/mamujoco_list.py so it is registered."
        )


# -- PettingZoo conformance, every registered scenario x preset ------------------------------------
# Slow: tests/test_conformance.py runs these two checks (with more cycles) on the same registered
# scenarios, each with its ``full`` preset and each preset once in the default suite.
@pytest.mark.slow
@pytest.mark.parametrize(("sid", "preset"), CASES)
def test_pettingzoo_parallel_api(sid: str, preset: str) -> None:
    game = advgame.make(sid, preset=preset)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            parallel_api_test(game, num_cycles=CYCLES)
    finally:
        game.close()


@pytest.mark.slow
@pytest.mark.parametrize(("sid", "preset"), CASES)
def test_pettingzoo_parallel_seed(sid: str, preset: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parallel_seed_test(lambda: advgame.make(sid, preset=preset), num_cycles=CYCLES)


# -- the task base --------------------------------------------------------------------------------
@pytest.mark.parametrize("sid", REGISTERED)
def test_task_base_wraps_the_mamujoco_env(sid: str) -> None:
    task = scenario_spec(sid).make_task()
    env = task.env
    assert task.protagonists == tuple(env.possible_agents)
    assert task.protagonists[0] == FIRST_AGENT  # the partial presets target it
    for a in task.protagonists:
        assert task.observation_spaces[a] is env.observation_space(a)
        assert task.action_spaces[a] is env.action_space(a)
    obs, _ = task.reset(seed=3)
    assert set(obs) == set(task.protagonists)
    for a in task.protagonists:
        assert task.observation_spaces[a].contains(obs[a]), a
    state = task.state(obs)
    assert isinstance(task.state_space, spaces.Box)
    assert state.shape == task.state_space.shape and task.state_space.contains(state)
    np.testing.assert_array_equal(state, env.state())
    inner = env.single_agent_env.unwrapped
    assert task.sim.model is inner.model and task.sim.data is inner.data
    assert task.max_episode_steps == env.single_agent_env.spec.max_episode_steps
    assert FORCES[VARIANTS[sid].scenario][0][0] in task.sim.names("body")
    task.close()


@pytest.mark.parametrize("sid", ["MA-Pusher-3p", "MA-HalfCheetah-2x3"])
def test_observation_layout_is_the_same_in_every_instance(sid: str) -> None:
    tasks = [scenario_spec(sid).make_task() for _ in range(4)]
    first = tasks[0]
    action = {a: np.full(s.shape, 0.3, s.dtype) for a, s in first.action_spaces.items()}
    runs = []
    for task in tasks:
        obs, _ = task.reset(seed=5)
        steps = [obs] + [task.step(action)[0] for _ in range(3)]
        runs.append(steps)
        for k_dict in task.env.k_dicts:  # every level in one canonical order
            for nodes in k_dict.values():
                keys = [(n.label, str(n.act_ids), str(n.qpos_ids)) for n in nodes]
                assert keys == sorted(keys)
    for run in runs[1:]:
        for i, (a, b) in enumerate(zip(runs[0], run, strict=True)):
            _assert_same(a, b, f"{sid} step {i}")


def test_pusher_still_has_duplicate_joint_labels_upstream() -> None:
    # Why MaMuJoCoTask fixes the observation layout: upstream labels two Pusher joints alike, so
    # agent_0's order follows set iteration. If this fails, upstream fixed the labels.
    from gymnasium_robotics.envs.multiagent_mujoco.obsk import get_parts_and_edges

    parts, _, _ = get_parts_and_edges("Pusher", "3p")
    counts = Counter(node.label for node in parts[0])
    assert counts["r_wrist_roll_joint"] == 2, counts


@pytest.mark.parametrize(
    ("scenario", "conf"), [("ManySegmentSwimmer", "5x4"), ("ManySegmentAnt", "2x3")]
)
def test_many_segment_models_are_generated_privately(scenario: str, conf: str) -> None:
    from gymnasium_robotics import mamujoco_v1

    task = MaMuJoCoTask(scenario, conf)
    upstream = mamujoco_v1.parallel_env(scenario, conf)  # the same robot, built by MaMuJoCo
    ours, theirs = task.env.single_agent_env.unwrapped, upstream.single_agent_env.unwrapped
    for count in ("nq", "nv", "nu", "nbody", "ngeom"):
        assert getattr(ours.model, count) == getattr(theirs.model, count), count
    assert task.observation_spaces == {a: upstream.observation_space(a) for a in task.protagonists}
    assert task.action_spaces == {a: upstream.action_space(a) for a in task.protagonists}
    path = ours.fullpath
    assert os.path.exists(path) and "site-packages" not in path
    assert (
        task.sim.spec.body("torso" if scenario == "ManySegmentSwimmer" else "torso_0") is not None
    )
    task.close()
    upstream.close()
    assert not os.path.exists(path)


def test_many_segment_tasks_build_in_concurrent_processes() -> None:
    # MaMuJoCo alone writes and deletes one shared file per robot: concurrent builds fail.
    code = (
        "from advgame.scenarios.mamujoco import MaMuJoCoTask\n"
        "for _ in range(25):\n"
        "    MaMuJoCoTask('ManySegmentSwimmer', '5x4').close()\n"
    )
    procs = [
        subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE, text=True)
        for _ in range(3)
    ]
    for proc in procs:
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, err[-2000:]


def test_task_step_copies_the_shared_info_and_takes_the_team_reward_once() -> None:
    task = MaMuJoCoTask("HalfCheetah", "2x3")
    seen: dict[str, Any] = {}
    real_step = task.env.step

    def spy(actions: dict) -> tuple:  # the real MaMuJoCo step, recording what it handed out
        seen["out"] = real_step(actions)
        return seen["out"]

    task.env.step = spy
    task.reset(seed=0)
    actions = {a: np.full(s.shape, 0.5, s.dtype) for a, s in task.action_spaces.items()}
    _, reward, cost, terminated, truncated, info = task.step(actions)
    _, rewards, _, _, infos = seen["out"]
    assert infos["agent_0"] is infos["agent_1"]  # MaMuJoCo shares one dict...
    assert info == infos["agent_0"] and all(info is not i for i in infos.values())  # ...we copy
    assert type(reward) is float and reward == rewards["agent_0"] == rewards["agent_1"]
    assert cost == 0.0 and not terminated and not truncated


def test_render_mode_is_recorded_and_rgb_frames_render() -> None:
    assert MaMuJoCoTask("Swimmer", "2x1").env.render_mode is None
    code = (
        "from advgame.scenarios.mamujoco import MaMuJoCoTask\n"
        "t = MaMuJoCoTask('HalfCheetah', '2x3', render_mode='rgb_array')\n"
        "assert t.env.render_mode == 'rgb_array', t.env.render_mode\n"
        "t.reset(seed=0)\n"
        "frame = t.render()\n"
        "assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0, frame.shape\n"
        "t.close()\n"
    )
    env = {**os.environ, "MUJOCO_GL": "egl"}  # headless OpenGL, in a process of its own
    proc = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr[-2000:]


# -- games: isolation, partial attacks, team zero-sum, the shared model, determinism -------------
def test_each_protagonist_gets_its_own_info_dict() -> None:
    game = advgame.make("MA-HalfCheetah-2x3", preset="full")
    _, infos = game.reset(seed=1)
    moves = [infos]
    while len(moves) < 6:
        moves.append(game.step({a: game.action_space(a).sample() for a in game.agents})[4])
    for infos in moves:
        p0, p1 = (infos[p] for p in game.protagonists)
        assert p0 is not p1 and p0 == p1
        p0["x_position"] = "mutated"
        p0["extra"] = 1
        assert p1.get("x_position") != "mutated" and "extra" not in p1
    assert any("true_reward" in infos["agent_1"] for infos in moves)  # act moves were checked


@pytest.mark.parametrize("sid", ["MA-HalfCheetah-2x3", "MA-Hopper-3x1", "MA-Ant-4x2"])
def test_partial_preset_attacks_only_the_first_agent(sid: str) -> None:
    game = advgame.make(sid, preset="partial")
    assert game.disruptors["observation_adversary"].targets == (FIRST_AGENT,)
    assert game.disruptors["action_adversary"].targets == (FIRST_AGENT,)
    others = game.protagonists[1:]
    ctrl = game.task.sim.data.ctrl
    true_obs, _ = game.reset(seed=2)
    rng = np.random.default_rng(0)
    for _ in range(5):
        assert game.next_movers == {"observation_adversary"}  # a sense move: s_t is true
        ones = {a: np.ones(game.action_space(a).shape, np.float32) for a in game.agents}
        shown = game.step(ones)[0]
        np.testing.assert_allclose(shown[FIRST_AGENT] - true_obs[FIRST_AGENT], 0.1, rtol=1e-9)
        for p in others:
            assert np.array_equal(shown[p], true_obs[p]), p
        acts = {
            p: rng.uniform(-0.5, 0.5, game.action_space(p).shape).astype(np.float32)
            for p in game.protagonists
        }
        true_obs = game.step({**ones, **acts})[0]  # the act move returns the true next state
        sent = game.task.env.map_global_action_to_local_actions(ctrl)
        np.testing.assert_allclose(sent[FIRST_AGENT], acts[FIRST_AGENT] + 0.1, atol=1e-6)
        for p in others:
            assert np.array_equal(sent[p], acts[p].astype(np.float64)), p
    game.close()


@pytest.mark.parametrize("kind", ["state", "action", "reward"])
def test_paper_partial_noise_presets_disrupt_only_the_first_agent(kind: str) -> None:
    preset = f"{kind}-gauss-0.1-partial"
    spec = advgame.core.registry.scenario_spec("MA-HalfCheetah-2x3").load_presets()[preset]
    game = advgame.make("MA-HalfCheetah-2x3", preset=preset)
    (adversary,) = game.adversaries
    assert set(spec.adversaries) == {adversary}  # the Gaussian noise is given for that agent
    assert game.disruptors[adversary].targets == (FIRST_AGENT,)
    other = game.protagonists[1]
    true_obs, _ = game.reset(seed=3)
    ctrl = game.task.sim.data.ctrl
    push = {adversary: np.full(game.action_space(adversary).shape, 0.3, np.float32)}
    zero = {p: np.zeros(game.action_space(p).shape, np.float32) for p in game.protagonists}
    if kind == "state":  # the observation adversary moves first, on the true state
        shown = game.step({**zero, **push})[0]
        assert np.array_equal(shown[other], true_obs[other])
        np.testing.assert_allclose(shown[FIRST_AGENT] - true_obs[FIRST_AGENT], 0.3, rtol=1e-6)
    _, rewards, _, _, infos = game.step({**zero, **push})  # act move
    sent = game.task.env.map_global_action_to_local_actions(ctrl)
    assert np.array_equal(sent[other], zero[other])
    if kind == "action":
        np.testing.assert_allclose(sent[FIRST_AGENT], 0.3, rtol=1e-6)
    else:
        assert np.array_equal(sent[FIRST_AGENT], zero[FIRST_AGENT])
    true = infos[other]["true_reward"]
    assert rewards[other] == true
    assert (kind == "reward") == (rewards[FIRST_AGENT] == pytest.approx(true + 0.3))
    game.close()


@pytest.mark.parametrize(
    ("sid", "preset"),
    [
        ("MA-HalfCheetah-2x3", "full"),
        ("MA-Ant-4x2", "full"),
        ("MA-ManySegmentSwimmer-5x4", "reward-gauss-0.1"),
    ],
)
def test_team_zero_sum_on_the_true_reward(sid: str, preset: str) -> None:
    game = advgame.make(sid, preset=preset, max_episode_steps=15)
    _, _ = game.reset(seed=4)
    for i, a in enumerate(game.possible_agents):
        game.action_space(a).seed(i)
    act_moves = observed_differs = 0
    while game.agents:
        _, rewards, _, _, infos = game.step({a: game.action_space(a).sample() for a in game.agents})
        if not infos[FIRST_AGENT]["acted"]:  # sense move: nobody is paid
            assert set(rewards.values()) == {0.0}
            continue
        act_moves += 1
        true = infos[FIRST_AGENT]["true_reward"]
        assert isinstance(true, float)
        for p in game.protagonists:
            assert infos[p]["true_reward"] == true and infos[p]["payoff"] == true
            observed_differs += rewards[p] != true
        for adversary in game.adversaries:
            assert rewards[adversary] == -true, adversary
    assert 0 < act_moves == game.t <= 15
    assert observed_differs > 0  # the reward adversary changed what protagonists observe
    game.close()


@pytest.mark.parametrize("sid", ["MA-HalfCheetah-2x3", "MA-ManySegmentAnt-2x3"])
def test_dynamics_and_force_edit_the_shared_model_and_reset_restores_it(sid: str) -> None:
    game = advgame.make(sid, preset="full")
    sim, inner = game.task.sim, game.task.env.single_agent_env.unwrapped
    m = sim.model
    fields = ("body_mass", "body_inertia", "geom_friction", "dof_damping", "actuator_gear")
    nominal = {f: getattr(m, f).copy() for f in fields}
    gravity = m.opt.gravity.copy()
    force = game.disruptors["force_adversary"]
    game.reset(seed=0)
    ones = {a: np.ones(game.action_space(a).shape, np.float32) for a in game.agents}
    before = game.step(ones)[0]  # sense move
    obs = game.step(ones)[0]  # act move: dynamics at 1.2 x nominal, forces at their bound
    assert m is inner.model and sim.data is inner.data  # what MaMuJoCo steps is what we edit
    np.testing.assert_allclose(m.body_mass[1:], 1.2 * nominal["body_mass"][1:])
    np.testing.assert_allclose(m.opt.gravity, 1.2 * gravity)
    np.testing.assert_allclose(m.geom_friction[:, 0], 1.2 * nominal["geom_friction"][:, 0])
    np.testing.assert_allclose(m.actuator_gear[:, 0], 1.2 * nominal["actuator_gear"][:, 0])
    np.testing.assert_allclose(m.dof_damping, 1.2 * nominal["dof_damping"])
    applied = sim.data.xfrc_applied[np.ix_(force.ids, force.cols)]
    np.testing.assert_allclose(applied, FORCES[VARIANTS[sid].scenario][2])
    np.testing.assert_array_equal(game.state(), game.task.env.state())
    assert not np.array_equal(obs[FIRST_AGENT], before[FIRST_AGENT])
    game.reset(seed=0)
    for f in fields:
        np.testing.assert_array_equal(getattr(m, f), nominal[f], err_msg=f)
    np.testing.assert_array_equal(m.opt.gravity, gravity)
    assert not sim.data.xfrc_applied.any()
    game.close()


def _episode(sid: str, preset: str, seed: int) -> list[tuple]:
    """A full episode: the preset's random adversaries, seeded samples for everyone else."""
    game = advgame.make(sid, preset=preset, max_episode_steps=20)
    suggested = game.preset.adversaries
    policies = {a: spec.build(game.agent_info(a)) for a, spec in suggested.items()}
    obs, infos = game.reset(seed=seed)
    for i, a in enumerate(game.possible_agents):
        game.action_space(a).seed(seed + i)
    for k, policy in enumerate(policies.values()):
        policy.reset(seed=seed + 100 + k)
    moves: list[tuple] = [(obs, infos)]
    while game.agents:
        actions = {a: game.action_space(a).sample() for a in game.agents}
        for a, policy in policies.items():
            actions[a] = policy.act(obs[a])
        obs, *rest = game.step(actions)
        moves.append((obs, *rest))
    assert game.t == 20 or any(moves[-1][2].values())  # truncated at the horizon, or terminated
    game.close()
    return moves


@pytest.mark.parametrize(
    ("sid", "preset"),
    [
        ("MA-HalfCheetah-2x3", "full"),
        ("MA-Hopper-3x1", "state-gauss-0.1-partial"),
        ("MA-Humanoid-9|8", "action-gauss-0.1"),
    ],
)
def test_seeded_full_episode_is_deterministic(sid: str, preset: str) -> None:
    first, second = _episode(sid, preset, 11), _episode(sid, preset, 11)
    assert len(first) == len(second) > 2
    for i, (a, b) in enumerate(zip(first, second, strict=True)):
        for j, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_same(x, y, f"move {i} output {j}")
    other = _episode(sid, preset, 12)
    last = min(len(other), len(first)) - 1
    assert not np.array_equal(other[last][0][FIRST_AGENT], first[last][0][FIRST_AGENT])
