"""OMPO's non-stationary tasks (`advgame.scenarios.ompo`) and evaluation columns that play them.

The live model of each preset is read back in episode ``i`` and compared with OMPO's formulas
(Roythuly/OMPO, ``main_non_stationary.py`` lines 85-100) and edits (``Non_stationary_env``):
capsule half-lengths, body positions, unchanged masses, gravity, wind, viscosity, density. An
evaluation column of a per-episode schedule plays episode ``s·E + e + 1`` in seed ``s``'s
episode ``e`` (`schedule_index`), however the jobs are cut.
"""

from __future__ import annotations

import copy
from typing import Any

import mujoco
import numpy as np
import pytest

import advgame
from advgame.adversaries import ConstantAdversary, SinusoidAdversary
from advgame.core.episodes import rollout
from advgame.disruptors import DynamicsDisruptor, Param
from advgame.errors import ConfigError
from advgame.evaluation import (
    SEED_STRIDE,
    AdversarySetup,
    EvalJob,
    evaluate,
    lockstep_groups,
    population_jobs,
    schedule_index,
    split_seeds,
)
from advgame.evaluation.table.batched import play_job_sequential, play_jobs
from advgame.scenarios.ompo import OMPO_TASKS

P, DYN = "protagonist", "dynamics_adversary"
PRESETS = ("ompo-nonstationary", "ompo-low", "ompo-mid", "ompo-high")


def ompo(env_id: str, i: float) -> tuple[float, float]:
    """OMPO's value pair in training episode `i` (main_non_stationary.py lines 85-100)."""
    if env_id == "Hopper-v5":
        return 0.4 + 0.1 * np.sin(0.2 * i), 0.39 + 0.1 * np.sin(0.2 * i)
    if env_id == "Walker2d-v5":
        return 0.2 + 0.1 * np.sin(0.3 * i), 0.1 + 0.05 * np.sin(0.3 * i)
    wind = 0.2 if env_id == "Ant-v5" else 0.5
    return 14.715 + 4.905 * np.sin(0.5 * i), 1.0 + wind * np.sin(0.5 * i)


def _zero(obs: Any) -> np.ndarray:
    return np.zeros(3, dtype=np.float32)


def _ids(model: Any, kind: Any, *names: str) -> list[int]:
    return [mujoco.mj_name2id(model, kind, n) for n in names]


def _snapshot(sim: Any) -> dict[str, np.ndarray]:
    m = sim.model
    return {
        "size": m.geom_size.copy(), "pos": m.body_pos.copy(), "mass": m.body_mass.copy(),
        "inertia": m.body_inertia.copy(), "ipos": m.body_ipos.copy(),
        "gravity": m.opt.gravity.copy(), "wind": m.opt.wind.copy(),
        "density": np.array(m.opt.density), "viscosity": np.array(m.opt.viscosity),
        "rbound": m.geom_rbound.copy(),
    }  # fmt: skip


def _check_ompo_model(env_id: str, got: dict[str, np.ndarray], nominal: dict, i: float) -> None:
    """The live model in episode `i` is OMPO's (its files' edits, lines cited in the module)."""
    a, b = ompo(env_id, i)
    tol = 1e-6  # the adversary's action is a float32
    for key in ("mass", "inertia", "ipos"):  # OMPO edits the compiled model: masses stay
        assert np.array_equal(got[key], nominal[key]), key
    if env_id in ("Hopper-v5", "Walker2d-v5"):
        torso_len, foot_len = a, b
        # hopper_random.py L26-30, walker2d_random.py L27-33 (indices = v5 names, checked below)
        assert got["pos"][1, 2] == pytest.approx(1.05 + torso_len, abs=tol)
        assert got["pos"][2, 2] == pytest.approx(-torso_len, abs=tol)
        assert got["size"][1, 1] == pytest.approx(torso_len, abs=tol)
        assert got["size"][4, 1] == pytest.approx(foot_len, abs=tol)
        if env_id == "Walker2d-v5":
            assert got["pos"][5, 2] == pytest.approx(-torso_len, abs=tol)
            assert got["size"][7, 1] == pytest.approx(foot_len, abs=tol)
        assert got["rbound"][4] == pytest.approx(got["size"][4, 0] + foot_len, abs=tol)
        assert np.array_equal(got["gravity"], nominal["gravity"])
        return
    gravity, wind = a, b  # ant_random.py / humanoid_random.py L21-22, L37-38
    np.testing.assert_allclose(got["gravity"], [0.0, 0.0, -gravity], atol=1e-5)
    np.testing.assert_allclose(got["wind"], [-wind, 0.0, 0.0], atol=tol)
    assert float(got["viscosity"]) == 0.00002 and float(got["density"]) == 1.2
    assert np.array_equal(got["size"], nominal["size"])


def test_ompo_indices_are_the_v5_models_names() -> None:
    # OMPO writes gym v3's arrays by index; the v5 models have the same bodies at those indices
    cases = [("Hopper-v5", ("foot_geom",)), ("Walker2d-v5", ("foot_geom", "foot_left_geom"))]
    for env_id, feet in cases:
        game = advgame.make(env_id)
        m = game.task.sim.model
        bodies = ("torso", "thigh", "thigh_left")[: 2 if env_id == "Hopper-v5" else 3]
        assert _ids(m, mujoco.mjtObj.mjOBJ_BODY, *bodies) == [1, 2, 5][: len(bodies)]
        assert _ids(m, mujoco.mjtObj.mjOBJ_GEOM, "torso_geom", *feet) == [1, 4, 7][: 1 + len(feet)]
        assert m.body_pos[1, 2] == pytest.approx(1.05 + 0.2)  # OMPO's 1.05 + torso_len
        assert m.geom_size[1, 1] == pytest.approx(0.2)  # the torso's nominal half-length
        game.close()


@pytest.mark.parametrize("env_id", sorted(OMPO_TASKS))
def test_presets_say_where_their_numbers_come_from(env_id: str) -> None:
    from advgame.core.registry import scenario_spec

    presets = scenario_spec(env_id).load_presets()
    task = OMPO_TASKS[env_id]
    for name in PRESETS:
        assert "main_non_stationary.py L" in presets[name].description
        assert "_random.py L" in presets[name].description
    assert tuple(p.low for p in task.params) == task.value(-1)  # the intervals' ends
    assert tuple(p.high for p in task.params) == task.value(1)
    for i in (1, 2):
        wave = np.array(task.base) + np.array(task.amplitude) * np.sin(task.frequency * i)
        assert wave == pytest.approx(ompo(env_id, i))
    wave = presets["ompo-nonstationary"].adversaries[DYN]
    assert isinstance(wave, SinusoidAdversary) and wave.start == 1


@pytest.mark.parametrize("env_id", sorted(OMPO_TASKS))
def test_nonstationary_preset_is_ompos_model_in_episode_i(env_id: str) -> None:
    game = advgame.make(env_id, preset="ompo-nonstationary", max_episode_steps=2)
    sim = game.task.sim
    nominal = _snapshot(sim)
    seen: dict[int, dict[int, dict[str, np.ndarray]]] = {}
    episode = [0]

    def protagonist(obs: Any) -> np.ndarray:
        if game.t == 0:
            episode[0] += 1
        seen.setdefault(episode[0], {})[game.t] = _snapshot(sim)
        return np.zeros(game.action_space(P).shape, dtype=np.float32)

    try:
        wave = game.preset.adversaries[DYN]
        results = rollout(game, {P: protagonist, DYN: wave}, seed=0, episodes=3)
    finally:
        game.close()
    assert sorted(seen) == [1, 2, 3] and all(r.clipped[DYN] == 0 for r in results)
    for i, steps in seen.items():  # OMPO's loop counts from 1: the first episode is i = 1
        for key, value in nominal.items():  # t = 0: the nominal model, nothing leaked
            assert np.array_equal(steps[0][key], value), (i, key)
        _check_ompo_model(env_id, steps[1], nominal, i)


@pytest.mark.parametrize("env_id", sorted(OMPO_TASKS))
@pytest.mark.parametrize(("preset", "sign"), [("ompo-low", -1), ("ompo-mid", 0), ("ompo-high", 1)])
def test_fixed_points_hold_the_ranges_ends_and_centre(env_id: str, preset: str, sign: int) -> None:
    game = advgame.make(env_id, preset=preset, max_episode_steps=2)
    sim = game.task.sim
    nominal = _snapshot(sim)
    try:
        game.reset(seed=0)
        noop = np.zeros(game.action_space(P).shape, dtype=np.float32)
        act = game.preset.adversaries[DYN].build(game.agent_info(DYN)).act(None)
        game.step({P: noop, DYN: act})
        got = _snapshot(sim)
    finally:
        game.close()
    # sin(ω·i) = sign: the formulas at the range's end or centre
    i = {-1: 3 * np.pi / 2, 0: 0.0, 1: np.pi / 2}[sign] / OMPO_TASKS[env_id].frequency
    _check_ompo_model(env_id, got, nominal, i)


@pytest.mark.parametrize("env_id", ["Hopper-v5", "Walker2d-v5"])
def test_torso_grows_up_from_the_hip_and_the_foot_at_both_ends(env_id: str) -> None:
    game = advgame.make(env_id, preset="ompo-high", max_episode_steps=2)
    sim = game.task.sim
    m = sim.model
    torso, thigh, foot = m.geom("torso_geom").id, m.body("thigh").id, m.geom("foot_geom").id
    nominal_masses = m.body_mass.copy()

    def frame() -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        data = mujoco.MjData(sim.model)  # the initial pose, qpos0
        mujoco.mj_kinematics(sim.model, data)
        top = data.geom_xpos[torso, 2] + sim.model.geom_size[torso, 1]
        axis = data.geom_xmat[foot].reshape(3, 3)[:, 2]
        half = sim.model.geom_size[foot, 1]
        ends = [data.geom_xpos[foot] + s * half * axis for s in (-1, 1)]
        return top, data.xpos[thigh].copy(), data.geom_xpos[foot].copy(), np.array(ends)

    try:
        top0, hip0, foot0, ends0 = frame()
        game.reset(seed=0)
        act = game.preset.adversaries[DYN].build(game.agent_info(DYN)).act(None)
        game.step({P: np.zeros(game.action_space(P).shape, np.float32), DYN: act})
        top, hip, foot_centre, ends = frame()
        masses = sim.model.body_mass.copy()
    finally:
        game.close()
    torso_len, foot_len = OMPO_TASKS[env_id].value(1)
    half0 = {"Hopper-v5": 0.195, "Walker2d-v5": 0.1}[env_id]
    assert top - top0 == pytest.approx(2 * (torso_len - 0.2), abs=1e-9)  # the torso's top rises
    assert np.allclose(hip, hip0, atol=1e-12) and np.allclose(foot_centre, foot0, atol=1e-12)
    grown = np.linalg.norm(ends - ends0, axis=1)  # each foot tip moves out by the change
    assert grown == pytest.approx([foot_len - half0] * 2, abs=1e-9)
    assert np.array_equal(masses, nominal_masses)


@pytest.mark.parametrize("env_id", ["Hopper-v5", "Walker2d-v5"])
def test_collision_bounds_are_those_of_a_compile_of_the_shifted_shape(env_id: str) -> None:
    game = advgame.make(env_id, preset="ompo-high", max_episode_steps=2)
    sim = game.task.sim
    try:
        game.reset(seed=0)
        act = game.preset.adversaries[DYN].build(game.agent_info(DYN)).act(None)
        game.step({P: np.zeros(game.action_space(P).shape, np.float32), DYN: act})
        live = sim.model
        spec = sim.spec.copy()  # the nominal model's spec, edited as OMPO edits the model
        torso_len, foot_len = OMPO_TASKS[env_id].value(1)
        spec.body("torso").pos = [0, 0, 1.05 + torso_len]
        for name in ("thigh", "thigh_left")[: 1 if env_id == "Hopper-v5" else 2]:
            spec.body(name).pos = [0, 0, -torso_len]
        spec.geom("torso_geom").size = [0.05, torso_len, 0]
        for name in ("foot_geom", "foot_left_geom")[: 1 if env_id == "Hopper-v5" else 2]:
            spec.geom(name).size = [0.06, foot_len, 0]
        compiled = spec.compile()
        for field in ("body_pos", "geom_size", "geom_rbound", "geom_aabb", "bvh_aabb"):
            np.testing.assert_allclose(
                getattr(live, field), getattr(compiled, field), atol=1e-6, err_msg=field
            )
        # OMPO keeps the nominal masses, which a compile would change
        assert not np.allclose(live.body_mass, compiled.body_mass)
    finally:
        game.close()


def test_a_tilted_long_foot_touches_the_floor() -> None:
    # OMPO's stale bounds would miss this contact (measured: no contact, 5 mm deep)
    long_foot = DynamicsDisruptor(params=[Param("capsule", 0.6, 0.6, names=("foot",))])
    game = advgame.make("Hopper-v5", disruptors=[long_foot])
    sim = game.task.sim
    try:
        game.reset(seed=0)
        game.step({P: np.zeros(3, np.float32), DYN: np.zeros(1, np.float32)})
        model = sim.model
        data = mujoco.MjData(model)
        data.qpos[:] = [0.0, 1.55, 0.0, 0.0, 0.0, 0.7]
        mujoco.mj_forward(model, data)
        assert data.ncon == 1
        stale = copy.copy(model)  # OMPO's edit alone: the nominal foot's bounds
        g, node = model.geom("foot_geom").id, model.body_bvhadr[model.body("foot").id]
        stale.geom_rbound[g], stale.geom_aabb[g, 5] = 0.06 + 0.195, 0.06 + 0.195
        stale.bvh_aabb[node, 5] = 0.06 + 0.195
        mujoco.mj_forward(stale, data)
        assert data.ncon == 0
    finally:
        game.close()


def test_capsule_and_wind_options_are_checked() -> None:
    with pytest.raises(ConfigError, match="anchor"):
        Param("length", 0.3, 0.5, names=("torso",), anchor="base")
    with pytest.raises(ConfigError, match="axis"):
        Param("gravity", 9.0, 10.0, axis=(-1.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match="unit vector"):
        Param("wind", 0.0, 1.0, axis=(2.0, 0.0, 0.0))
    unnamed = DynamicsDisruptor(params=[Param("capsule", 0.1, 0.2)])
    with pytest.raises(ConfigError, match="names"):
        advgame.make("Hopper-v5", disruptors=[unnamed])
    sphere = DynamicsDisruptor(params=[Param("capsule", 0.1, 0.2, names=("torso",))])
    with pytest.raises(ConfigError, match="no capsule"):  # the Ant's torso is a sphere
        advgame.make("Ant-v5", disruptors=[sphere])


def test_sinusoid_counts_its_own_episodes_unless_told_which() -> None:
    game = advgame.make("Ant-v5", preset="ompo-nonstationary")
    info = game.agent_info(DYN)
    game.close()
    pol = SinusoidAdversary((14.715, 1.0), (4.905, 0.2), 0.5, start=1).build(info)

    def played() -> int:
        pol.reset(None)
        return int(pol.episode)  # type: ignore[attr-defined]

    assert [played(), played(), played()] == [1, 2, 3]  # training views: their own count
    pol.set_episode_index(7)  # type: ignore[attr-defined]
    assert [played(), played()] == [7, 8]
    with pytest.raises(ConfigError, match="start"):
        SinusoidAdversary(start=-1).build(info)


# -- evaluation columns ---------------------------------------------------------------------
STEPS = 30
SEEDS = (0, 1, 2)


def _jobs(preset: str, episodes: int = 1) -> list[EvalJob]:
    from advgame.core.registry import scenario_spec

    adversaries = dict(scenario_spec("Hopper-v5").load_presets()[preset].adversaries)
    setups = {
        "nominal": AdversarySetup({"disruptors": {}, "max_episode_steps": STEPS}),
        preset: AdversarySetup({"preset": preset, "max_episode_steps": STEPS}, adversaries),
    }
    return population_jobs("Hopper-v5", {"zero": _zero}, setups, seeds=SEEDS, episodes=episodes)


def _returns(rows: list[dict[str, Any]], adversary: str) -> list[float]:
    return [r["true_return"] for r in rows if r["adversary"] == adversary]


def _at_index(preset: str, index: int, seed: int) -> float:
    """The return of one episode with the schedule's value of episode `index` held constant."""
    game = advgame.make("Hopper-v5", preset=preset, phase="eval", max_episode_steps=STEPS)
    wave = game.preset.adversaries[DYN]
    value = np.asarray(wave.base) + np.asarray(wave.amplitude) * np.sin(wave.frequency * index)
    try:
        played = rollout(game, {P: _zero, DYN: ConstantAdversary(tuple(value))}, seed=seed)
    finally:
        game.close()
    return played[0].true_return


@pytest.mark.parametrize("preset", ["ompo-nonstationary", "shift-sinusoid"])
def test_a_scheduled_column_plays_episode_s_plus_1_in_seed_s(preset: str) -> None:
    rows = evaluate(_jobs(preset), progress=False).rows
    nominal, shifted = _returns(rows, "nominal"), _returns(rows, preset)
    assert [schedule_index(s, 0, 1) for s in SEEDS] == [1, 2, 3]
    want = [_at_index(preset, s + 1, s * SEED_STRIDE) for s in SEEDS]
    assert shifted == want  # bit for bit: seed s played the schedule's episode s + 1
    assert all(a != b for a, b in zip(shifted, nominal, strict=True))
    assert len(set(shifted)) == len(SEEDS)  # the shift moves from seed to seed


def test_the_schedule_does_not_depend_on_how_the_jobs_are_cut() -> None:
    jobs = _jobs("ompo-nonstationary", episodes=2)
    whole = [row for rows in play_jobs(jobs) for row in rows]
    units = [row for u in split_seeds(jobs, 1) for row in play_jobs([u])[0]]
    cut = lockstep_groups(split_seeds(jobs, 2), 3)
    groups = [row for g in cut for rows in play_jobs(list(g)) for row in rows]
    alone = [row for job in jobs for row in play_job_sequential(job)]
    key = [(r["adversary"], r["seed"], r["episode"]) for r in whole]
    for other in (units, groups, alone):
        assert sorted(
            (r["adversary"], r["seed"], r["episode"], r["true_return"]) for r in other
        ) == sorted((r["adversary"], r["seed"], r["episode"], r["true_return"]) for r in whole)
    shifted = {
        (s, e): r["true_return"] for (a, s, e), r in zip(key, whole, strict=True) if a != "nominal"
    }
    # seed s, episode e of two plays schedule episode 2s + e + 1
    assert shifted[(1, 1)] == _at_index("ompo-nonstationary", 4, SEED_STRIDE + 1)
    assert len(set(shifted.values())) == len(shifted)


def test_the_training_quick_eval_plays_a_shifted_episode(tmp_path: Any) -> None:
    import csv

    from advgame.training import TrainConfig, train

    config = TrainConfig(
        scenario="Hopper-v5", preset="ompo-nonstationary", learned=[], iterations=1,
        protagonist_steps=64, protagonist_hparams={"n_steps": 64, "batch_size": 64},
        eval_episodes=1, task_options={"max_episode_steps": 60},
    )  # fmt: skip
    run = train(config, tmp_path / "run", progress=False)
    with (run / "progress.csv").open(newline="") as f:
        [row] = list(csv.DictReader(f))
    # episode 1 of the schedule (episode 0 would be the nominal body: sin(0) = 0)
    assert float(row["eval_attacked_return"]) != float(row["eval_nominal_return"])
