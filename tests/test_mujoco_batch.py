"""The batched MuJoCo task is SyncVectorEnv of ``gymnasium.make(id)``, bit for bit, only faster."""

from __future__ import annotations

import time
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from advgame.core.physics import THREADS_VAR, ThreadedStepper, default_threads, shared_stepper
from advgame.errors import ConfigError, UnknownNameError
from advgame.scenarios.mujoco_batch import TASKS, BatchedMujocoEnv
from tests._dynamics_helpers import install_recompiled_model


@pytest.fixture(autouse=True)
def _threads_whatever_the_batch_costs(monkeypatch: pytest.MonkeyPatch) -> None:
    """Split even small batches over the threads, so that the threaded path is what is tested."""
    monkeypatch.setattr(ThreadedStepper, "MIN_BATCH_SECONDS", 0.0)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


def _play_both(
    env_id: str,
    *,
    n: int = 3,
    steps: int = 150,
    limit: int = 40,
    threads: int = 2,
    dtype: type = np.float32,
    scale: float = 1.0,
    **kwargs: object,
) -> int:
    """Step SyncVectorEnv and the batched env with the same seeds and actions; episode ends."""
    ref = gym.vector.SyncVectorEnv(
        [lambda: gym.make(env_id, max_episode_steps=limit, **kwargs)] * n
    )
    batch = BatchedMujocoEnv(env_id, n, threads=threads, max_episode_steps=limit, **kwargs)
    try:
        obs_ref, info_ref = ref.reset(seed=11)
        obs, info = batch.reset(seed=11)
        assert _same(obs_ref, obs)
        assert info_ref.keys() == info.keys()
        rng = np.random.default_rng(3)
        low, high = ref.single_action_space.low, ref.single_action_space.high
        ends = 0
        for t in range(steps):
            actions = (scale * rng.uniform(low, high, (n, len(low)))).astype(dtype)
            expected, got = ref.step(actions), batch.step(actions)
            for name, a, b in zip(
                ("obs", "reward", "terminated", "truncated"), expected, got, strict=False
            ):
                assert _same(a, b), f"{env_id} step {t}: {name} differs: {a} vs {b}"
            assert expected[4].keys() == got[4].keys(), f"{env_id} step {t}: info keys"
            for key, value in expected[4].items():
                assert _same(value, got[4][key]), f"{env_id} step {t}: info[{key!r}] differs"
            ends += int(np.sum(expected[2] | expected[3]))
        return ends
    finally:
        ref.close()
        batch.close()


@pytest.mark.parametrize("env_id", TASKS)
def test_every_task_is_bit_for_bit_the_gymnasium_env_across_resets(env_id: str) -> None:
    ends = _play_both(env_id)
    assert ends >= 3  # episodes ended (time limit or health) and the copies were reset


def test_healthy_range_terminations_match_on_hopper_and_walker() -> None:
    # large random actions topple them well within the time limit
    for env_id in ("Hopper-v5", "Walker2d-v5"):
        ends = _play_both(env_id, limit=1000, steps=200, scale=1.0)
        assert ends >= 3, f"{env_id} never fell: the test would not exercise terminations"


def test_float64_actions_one_thread_and_task_keywords_match() -> None:
    _play_both("Hopper-v5", threads=1, dtype=np.float64, steps=80)
    _play_both("Ant-v5", steps=60, ctrl_cost_weight=0.25, include_cfrc_ext_in_observation=False)
    _play_both("HalfCheetah-v5", steps=60, exclude_current_positions_from_observation=False)


def test_reset_mask_resets_only_the_marked_copies() -> None:
    env = BatchedMujocoEnv("Hopper-v5", 3, threads=1)
    env.reset(seed=0)
    moved, *_ = env.step(np.ones((3, 3), np.float32))
    again, info = env.reset(seed=[5, 6, 7], options={"reset_mask": np.array([False, True, False])})
    single, _ = gym.make("Hopper-v5").reset(seed=6)
    assert np.array_equal(again[1], single)
    assert np.array_equal(again[[0, 2]], moved[[0, 2]])
    assert info["_x_position"].tolist() == [False, True, False]
    env.close()


def test_each_copys_own_timestep_edited_in_place_or_swapped_in_sets_its_dt() -> None:
    """The batched step reads every copy's timestep through options kept per batch: an edit in
    place and a swapped model (a dynamics disruptor's two ways) show, copy by copy."""
    n = 3
    batch = BatchedMujocoEnv("HalfCheetah-v5", n, threads=2)
    singles = [gym.make("HalfCheetah-v5") for _ in range(n)]
    try:
        obs, _ = batch.reset(seed=[4, 5, 6])
        for i, single in enumerate(singles):
            assert _same(single.reset(seed=4 + i)[0], obs[i])
        action = np.full((n, 6), 0.4, np.float32)
        for edit in (None, "timestep", "swap"):
            if edit == "timestep":
                for env in (batch.envs[1], singles[1].unwrapped):
                    env.model.opt.timestep = 0.02
            elif edit == "swap":
                for env in (batch.envs[2], singles[2].unwrapped):
                    install_recompiled_model(env, timestep=0.005)
            for _ in range(4):
                _, reward, _, _, info = batch.step(action)
                for i, single in enumerate(singles):
                    _, r, _, _, i_info = single.step(action[i])
                    assert reward[i] == r and info["x_velocity"][i] == i_info["x_velocity"]
        assert len(set(info["x_velocity"].tolist())) == n
    finally:
        batch.close()


def test_rows_taken_in_chunks_of_one_env_step_as_the_single_envs(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The threads take a split step's envs a chunk at a time (here one env a chunk, an odd
    count of envs): which thread steps which env changes nothing."""
    monkeypatch.setattr(ThreadedStepper, "CHUNK_SECONDS", 0.0)
    _play_both("Hopper-v5", n=5, steps=60)
    _play_both("Ant-v5", n=3, steps=40, threads=3)


def test_dynamics_edits_on_one_copy_change_only_that_copy() -> None:
    env = BatchedMujocoEnv("HalfCheetah-v5", 2, threads=2)
    env.reset(seed=[0, 0])
    env.envs[1].model.opt.gravity[2] = -3.0  # as a dynamics disruptor edits a copy's model
    for _ in range(20):
        obs, *_ = env.step(np.zeros((2, 6)))
    assert not np.array_equal(obs[0], obs[1])
    single = gym.make("HalfCheetah-v5")
    expected, _ = single.reset(seed=0)
    for _ in range(20):
        expected, *_ = single.step(np.zeros(6))
    assert np.array_equal(obs[0], expected)
    env.close()


def test_bad_input_gets_a_clear_error() -> None:
    with pytest.raises(UnknownNameError, match="Hopper-v5"):
        BatchedMujocoEnv("Hoper-v5", 2)
    with pytest.raises(ConfigError, match="num_envs"):
        BatchedMujocoEnv("Hopper-v5", 0)
    with pytest.raises(ConfigError, match="threads"):
        BatchedMujocoEnv("Hopper-v5", 2, threads=0)
    env = BatchedMujocoEnv("Hopper-v5", 2, threads=1)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros((2, 3)))
    env.reset(seed=0)
    with pytest.raises(ConfigError, match=r"shape \(2, 3\)"):
        env.step(np.zeros((2, 4)))
    with pytest.raises(ConfigError, match="seeds"):
        env.reset(seed=[1, 2, 3])
    env.close()


def test_threads_never_exceed_the_envs_and_default_to_the_cores(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    assert BatchedMujocoEnv("Reacher-v5", 1, threads=4).threads == 1
    assert BatchedMujocoEnv("Reacher-v5", 8).threads == min(8, default_threads())
    monkeypatch.setenv(THREADS_VAR, "1")
    assert default_threads() == 1
    assert shared_stepper() is shared_stepper(1)
    monkeypatch.setenv(THREADS_VAR, "two")
    with pytest.raises(ConfigError, match=THREADS_VAR):
        default_threads()


def test_vector_views_step_their_simulators_as_one_batch_and_play_the_single_episodes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from advgame import adversaries as adv
    from advgame.core.vector import VectorView
    from advgame.core.views import view_factory
    from advgame.scenarios import mujoco_batch

    calls: list[int] = []
    real = mujoco_batch.step_envs

    def counting(envs, *args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(len(envs))
        return real(envs, *args, **kwargs)

    monkeypatch.setattr(mujoco_batch, "step_envs", counting)
    policies = {
        "observation_adversary": adv.GaussianAdversary(std=0.05),
        "reward_adversary": adv.GaussianAdversary(std=0.05),
        "action_adversary": adv.GaussianAdversary(std=0.05),
        "force_adversary": adv.GaussianAdversary(std=0.5),
        "dynamics_adversary": adv.UniformAdversary(0.8, 1.2),
    }
    fns = [view_factory("Walker2d-v5", "protagonist", policies, preset="full") for _ in range(3)]
    vec, ref = VectorView(fns), DummyVecEnv(fns)
    vec.seed(5)
    ref.seed(5)
    assert np.array_equal(vec.reset(), ref.reset())
    rng = np.random.default_rng(0)
    resets = 0
    for t in range(120):
        actions = rng.uniform(-1, 1, (3, 6)).astype(np.float32)
        (o1, r1, d1, i1), (o2, r2, d2, i2) = vec.step(actions), ref.step(actions)
        assert np.array_equal(o1, o2) and np.array_equal(r1, r2) and np.array_equal(d1, d2), t
        assert [sorted(i) for i in i1] == [sorted(i) for i in i2]
        resets += int(d1.sum())
    assert resets >= 2
    assert calls and max(calls) == 3  # the three simulators stepped in one batch
    vec.close()
    ref.close()


def test_tasks_made_with_other_keywords_step_one_by_one() -> None:
    from advgame.scenarios.mujoco_batch import BatchedGymTask

    a, b = BatchedGymTask("Hopper-v5"), BatchedGymTask("Hopper-v5", ctrl_cost_weight=0.5)
    a.reset(seed=0)
    b.reset(seed=0)
    act = {"protagonist": np.full(3, 0.5, np.float32)}
    got = BatchedGymTask.step_many([a, b], [act, act])
    fresh = BatchedGymTask("Hopper-v5", ctrl_cost_weight=0.5)
    fresh.reset(seed=0)
    assert got[1][1] == fresh.step(act)[1]
    assert got[0][1] != got[1][1]


def test_a_batch_too_cheap_to_share_stays_on_the_calling_thread(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    envs = [gym.make("Hopper-v5").unwrapped for _ in range(4)]
    for i, env in enumerate(envs):
        env.reset(seed=i)
    twins = [gym.make("Hopper-v5").unwrapped for _ in range(4)]
    for i, env in enumerate(twins):
        env.reset(seed=i)
    monkeypatch.setattr(ThreadedStepper, "MIN_BATCH_SECONDS", 1e9)
    alone, shared = ThreadedStepper(2), ThreadedStepper(2)
    for _ in range(ThreadedStepper.PROBES + 3):
        alone.step(envs, np.full((4, 3), 0.3), nstep=4)
    assert not alone._relay.started  # measured, then judged not worth a second thread
    monkeypatch.setattr(ThreadedStepper, "MIN_BATCH_SECONDS", 0.0)
    for _ in range(ThreadedStepper.PROBES + 3):
        shared.step(twins, np.full((4, 3), 0.3), nstep=4)
    assert shared._relay.started  # measured PROBES times on the calling thread, then split
    assert all(np.array_equal(a.data.qpos, b.data.qpos) for a, b in zip(envs, twins, strict=True))
    shared.close()


def test_a_slow_first_step_does_not_split_a_cheap_batch_for_good(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The cost is the cheapest step seen: a slow first one (imports, cold caches, a preempted
    step) once made every later step of four Walker2d envs go to a second thread."""
    envs = [gym.make("Walker2d-v5").unwrapped for _ in range(4)]
    for i, env in enumerate(envs):
        env.reset(seed=i)
    monkeypatch.setattr(ThreadedStepper, "MIN_BATCH_SECONDS", 0.02)  # 5 ms an env: far above
    run, first = ThreadedStepper._run, [True]

    def slow_once(*args: Any) -> None:
        if first[0]:
            first[0] = False
            time.sleep(0.05)  # 12.5 ms an env: the first step alone says "split"
        run(*args)

    monkeypatch.setattr(ThreadedStepper, "_run", staticmethod(slow_once))
    stepper = ThreadedStepper(2, native=False)  # the loop patched above
    for _ in range(3 * ThreadedStepper.PROBES):
        stepper.step(envs, np.zeros((4, 6)), nstep=4)
    assert not stepper._relay.started
    (cost,) = stepper._cost.values()
    assert cost * 4 < 0.02
    stepper.close()
