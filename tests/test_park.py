"""Parking: a run in training carried to a fresh checkout resumes as if it had never moved."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.buffers import DictReplayBuffer, ReplayBuffer

from advgame.agents.common.replay_store import load_buffer, row_arrays, store_buffer
from advgame.agents.ompo.ompo import OMPOReplayBuffer
from advgame.cli import main
from advgame.errors import FileFormatError
from advgame.workflows.campaign import load_campaign


def _fill(buffer: ReplayBuffer, steps: int, rng: np.random.Generator, episode: int = 7) -> None:
    """`steps` transitions in episodes of `episode` steps (obs follow on within an episode)."""
    shape = buffer.obs_shape
    obs = rng.normal(size=(buffer.n_envs, *shape)).astype(np.float32)
    for t in range(steps):
        nxt = rng.normal(size=(buffer.n_envs, *shape)).astype(np.float32)
        done = np.full(buffer.n_envs, (t + 1) % episode == 0)
        action = rng.uniform(-1, 1, size=(buffer.n_envs, buffer.action_dim)).astype(np.float32)
        reward = rng.normal(size=buffer.n_envs).astype(np.float32)
        buffer.add(obs, nxt, action, reward, done, [{} for _ in range(buffer.n_envs)])
        obs = rng.normal(size=nxt.shape).astype(np.float32) if done[0] else nxt


def _same(a: ReplayBuffer, b: ReplayBuffer) -> None:
    assert (a.pos, a.full) == (b.pos, b.full)
    for name, array in row_arrays(a).items():
        np.testing.assert_array_equal(array, row_arrays(b)[name], err_msg=name)


def test_a_buffer_comes_back_bit_for_bit_and_a_later_store_adds_only_new_rows(
    tmp_path: Path,
) -> None:
    rng = np.random.default_rng(0)
    obs, act = spaces.Box(-5, 5, (11,)), spaces.Box(-1, 1, (3,))
    buffer = OMPOReplayBuffer(500, obs, act, device="cpu", n_envs=2)
    _fill(buffer, 120, rng)
    first = store_buffer(buffer, tmp_path)
    back = load_buffer(json.loads(json.dumps(first)), tmp_path)
    _same(buffer, back)
    assert len(back.initial) == len(buffer.initial) > 0  # OMPO's first states ride along
    # the chunk holds the filled rows only, next observations mostly as the next row's
    (chunk,) = first["chunks"]
    filled = sum(a[:120].nbytes for a in row_arrays(buffer).values())  # 120 of 500 rows
    assert (tmp_path / chunk["file"]).stat().st_size < 0.65 * filled  # (random rows: no zip gain)
    stamp = (tmp_path / chunk["file"]).stat().st_mtime_ns
    _fill(buffer, 60, rng)
    second = store_buffer(buffer, tmp_path, previous=first)
    assert second["chunks"][0] == chunk and len(second["chunks"]) == 2
    assert (tmp_path / chunk["file"]).stat().st_mtime_ns == stamp  # written once
    _same(buffer, load_buffer(second, tmp_path))
    # once the buffer wraps, rows under the old chunks change: everything is written again
    _fill(buffer, 400, rng)
    assert buffer.full
    third = store_buffer(buffer, tmp_path, previous=second)
    assert [(c["start"], c["end"]) for c in third["chunks"]] == [(0, buffer.buffer_size)]
    _same(buffer, load_buffer(third, tmp_path))


def test_dict_buffers_round_trip_and_a_missing_chunk_is_a_clear_error(tmp_path: Path) -> None:
    obs = spaces.Dict({"a": spaces.Box(-1, 1, (4,)), "b": spaces.Box(-1, 1, (2,))})
    buffer = DictReplayBuffer(50, obs, spaces.Box(-1, 1, (2,)), device="cpu")
    rng = np.random.default_rng(1)
    for _ in range(30):
        o = {k: rng.normal(size=(1, *s.shape)).astype(np.float32) for k, s in obs.spaces.items()}
        buffer.add(o, o, rng.normal(size=(1, 2)), np.ones(1), np.zeros(1), [{}])
    manifest = store_buffer(buffer, tmp_path)
    back = load_buffer(manifest, tmp_path)
    for key in ("a", "b"):
        np.testing.assert_array_equal(back.observations[key], buffer.observations[key])
        np.testing.assert_array_equal(back.next_observations[key], buffer.next_observations[key])
    assert buffer.observations["a"].shape[0] == 50  # the stored skeleton did not empty the original
    (tmp_path / manifest["chunks"][0]["file"]).unlink()
    with pytest.raises(FileFormatError, match="is missing"):
        load_buffer(manifest, tmp_path)


TINY = """
scenario = "Hopper-v5"
methods = ["sac"]
seeds = [0]

[train]
iterations = 3
protagonist_steps = 120
eval_episodes = 0
protagonist_hparams = { learning_starts = 40, buffer_size = 2000 }
"""


def _weights(run: Path) -> dict[str, np.ndarray]:
    from stable_baselines3 import SAC

    state = json.loads((run / "state.json").read_text())
    model = SAC.load(run / state["checkpoint"] / "protagonist.zip", device="cpu")
    return {k: v.numpy() for k, v in model.policy.state_dict().items()}


def _stopped_run(tmp_path: Path, done: int) -> tuple[Path, Path, Path]:
    """TINY's campaign file, its folder and its one run, trained `done` of its 3 iterations."""
    from advgame.training import train

    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY)
    out = tmp_path / "tiny"
    config = load_campaign(spec).config("sac-s0")
    run = out / "runs" / "sac-s0"
    train(dataclasses.replace(config, iterations=done), run, progress=False)  # stopped early
    saved = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**saved, "iterations": 3}))
    return spec, out, run


def test_a_parked_run_resumes_in_a_fresh_checkout_as_the_run_itself_would(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from advgame.training import resume

    spec, out, run = _stopped_run(tmp_path, 2)
    reference = tmp_path / "reference" / "sac-s0"
    shutil.copytree(run, reference)

    assert main(["campaign", str(spec), "--park"]) == 0
    assert "parked sac-s0 at iteration 2" in capsys.readouterr().out
    parked = out / "parked" / "sac-s0"
    assert not list(parked.rglob("*_replay.pkl"))  # the buffer is in chunks, not SB3's pickle
    assert list((parked / "replay" / "protagonist").glob("*.npz"))
    assert sorted(p.name for p in (parked / "checkpoints").iterdir()) == ["iter_0002"]

    shutil.rmtree(out / "runs")  # a fresh checkout: only what git carries
    manifest = parked / "checkpoints" / "iter_0002" / "protagonist_replay.json"
    good = manifest.read_text()
    manifest.write_text(good[: len(good) // 2])  # a damaged file is one clear line, no traceback
    assert main(["campaign", str(spec), "--stage", "train", "--no-progress"]) == 2
    assert "replay manifest" in capsys.readouterr().err
    assert not (out / "runs" / "sac-s0").exists()
    manifest.write_text(good)
    assert main(["campaign", str(spec), "--status"]) == 0
    assert "sac-s0: partial (2/3)" in capsys.readouterr().out
    assert main(["campaign", str(spec), "--stage", "train", "--no-progress"]) == 0
    assert not parked.exists() and (out / "finished" / "sac-s0").is_dir()

    resume(reference, progress=False)  # the same run, never moved
    mine, theirs = _weights(out / "finished" / "sac-s0"), _weights(reference)
    assert mine.keys() == theirs.keys()
    for name in mine:
        np.testing.assert_array_equal(mine[name], theirs[name], err_msg=name)


def test_parking_with_nothing_in_training_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY)
    assert main(["campaign", str(spec), "--park"]) == 0
    assert "parked 0 run(s)" in capsys.readouterr().out


def test_park_every_parks_on_each_tick_survives_a_failed_park_and_parks_on_interrupt() -> None:
    import threading

    from advgame.errors import ConfigError
    from advgame.workflows.park import ParkEvery

    calls: list[str] = []
    ticked = threading.Event()

    def park() -> dict[str, int]:
        calls.append("park")
        if len(calls) == 2:
            raise FileNotFoundError("a checkpoint deleted mid-park")  # logged, not raised
        if len(calls) >= 3:
            ticked.set()
        return {"sac-s0": len(calls)}

    with ParkEvery(park, 0.02) as parker:
        assert ticked.wait(30)  # the third tick came after the second one failed
    after = len(calls)
    assert parker.parks == after - 1  # every call but the failed one completed
    assert len(calls) == after  # leaving normally stops the ticks and parks nothing more

    with pytest.raises(KeyboardInterrupt), ParkEvery(park, 3600) as parker:
        raise KeyboardInterrupt
    assert len(calls) == after + 1 and parker.parks == 1  # one park on the way out
    with pytest.raises(ConfigError, match="> 0 seconds"):
        ParkEvery(park, 0)


def test_a_train_stage_with_park_every_leaves_a_parked_copy_when_it_is_killed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A session cut off mid-run (no ``--park``) still finds its run parked in ADVGAME_PARK."""
    import time

    import advgame.workflows.campaign as campaign_module
    from advgame.training import train
    from advgame.workflows.park import parked_iteration

    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY)
    outside = tmp_path / "outside"
    monkeypatch.setenv("ADVGAME_PARK", str(outside))
    parked = outside / "tiny" / "sac-s0"

    def cut_off(unit: tuple) -> str:
        config, partial, _, _ = unit
        train(dataclasses.replace(config, iterations=2), Path(partial), progress=False)
        deadline = time.monotonic() + 60
        while parked_iteration(parked) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)  # training goes on here; the parker's tick comes meanwhile
        assert parked_iteration(parked) == 2, "no periodic park while the run trained"
        raise KeyboardInterrupt  # the session ends

    monkeypatch.setattr(campaign_module, "_train_unit", cut_off)
    args = ["campaign", str(spec), "--stage", "train", "--workers", "1", "--no-progress"]
    assert main([*args, "--park-every", "-1"]) == 2
    assert "--park-every must be >= 0 minutes" in capsys.readouterr().err
    assert main([*args, "--park-every", "0.002"]) == 130  # every 0.12 s
    assert (
        f"parking the runs it trains every 0.002 min in {outside / 'tiny'}"
        in capsys.readouterr().out
    )
    assert parked_iteration(parked) == 2
    assert not (tmp_path / "tiny" / "parked").exists()  # ADVGAME_PARK's folder, not the tree's
    assert json.loads((parked / "config.json").read_text())["iterations"] == 2

    from advgame.cli.campaign import _park_minutes

    assert _park_minutes(None) == 30.0  # ADVGAME_PARK set: every half hour unless told
    monkeypatch.delenv("ADVGAME_PARK")
    assert (_park_minutes(None), _park_minutes(5.0)) == (0.0, 5.0)


def test_a_run_the_campaign_file_now_configures_otherwise_is_not_resumed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec, out, run = _stopped_run(tmp_path, 1)
    assert main(["campaign", str(spec), "--park"]) == 0  # a parked copy is checked the same way
    spec.write_text(TINY.replace("learning_starts = 40", "learning_starts = 60"))
    assert main(["campaign", str(spec), "--stage", "train", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "sac-s0 started with protagonist_hparams" in err and "learning_starts" in err
    assert json.loads((run / "state.json").read_text())["iteration"] == 1  # nothing trained
    spec.write_text(TINY)  # the file as the run started: it goes on
    assert main(["campaign", str(spec), "--stage", "train", "--no-progress"]) == 0
    assert (out / "finished" / "sac-s0").is_dir()
