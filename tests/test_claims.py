"""Two train stages of one campaign never train the same run: claims beside the runs."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from advgame.cli import main
from advgame.workflows.campaign import load_campaign
from advgame.workflows.campaign_status import write_status
from advgame.workflows.claims import claim_path, claimed, holder

TINY = """
scenario = "Hopper-v5"
methods = ["ppo"]
seeds = [0, 1]

[train]
iterations = 1
protagonist_steps = 128
eval_episodes = 0
protagonist_hparams = { n_steps = 64 }
"""


@pytest.fixture
def other() -> Iterator[subprocess.Popen[bytes]]:
    """Another live process on this host (the one that claims a run in these tests)."""
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    yield proc
    proc.kill()
    proc.wait()


def _claim_for(out: Path, run: str, pid: int, host: str | None = None) -> None:
    path = claim_path(out, run)
    path.parent.mkdir(parents=True, exist_ok=True)
    host = host or socket.gethostname()
    path.write_text(json.dumps({"pid": pid, "host": host, "since": 0.0}))


def test_a_run_claimed_by_a_live_process_is_left_to_it_until_that_process_ends(
    tmp_path: Path, other: subprocess.Popen[bytes]
) -> None:
    _claim_for(tmp_path, "a", other.pid)
    with claimed(tmp_path, ["a", "b"]) as mine:
        assert mine == ["b"]
        assert json.loads(claim_path(tmp_path, "b").read_text())["pid"] == os.getpid()
        with claimed(tmp_path, ["b"]) as again:  # this process holds it already
            assert again == ["b"]
    assert not claim_path(tmp_path, "b").exists()  # released when the block ends
    assert holder(tmp_path, "a") is not None  # the other process's claim stays
    other.kill()
    other.wait()
    assert holder(tmp_path, "a") is None  # its process ended: stale
    with claimed(tmp_path, ["a"]) as mine:
        assert mine == ["a"]


def test_a_claim_from_another_host_counts_and_a_damaged_one_does_not(tmp_path: Path) -> None:
    _claim_for(tmp_path, "a", 1, host="elsewhere")
    claim_path(tmp_path, "b").write_text('{"pid": ')  # killed while writing it
    with claimed(tmp_path, ["a", "b"]) as mine:
        assert mine == ["b"]
    with pytest.raises(RuntimeError), claimed(tmp_path, ["b"]):
        raise RuntimeError("a run that fails")
    assert not claim_path(tmp_path, "b").exists()  # released however the block ends


def test_a_second_train_stage_skips_the_run_another_one_trains(
    tmp_path: Path, other: subprocess.Popen[bytes], caplog: pytest.LogCaptureFixture
) -> None:
    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY)
    out = tmp_path / "tiny"
    _claim_for(out, "ppo-s0", other.pid)
    args = ["campaign", str(spec), "--workers", "1", "--no-progress", "--stage", "train"]
    assert main(args) == 0
    assert f"ppo-s0 is training in pid {other.pid}" in caplog.text
    assert not (out / "runs" / "ppo-s0" / "state.json").exists()  # not touched here
    assert (out / "finished" / "ppo-s1").is_dir()  # the other run trained
    assert not claim_path(out, "ppo-s1").exists()
    caplog.clear()
    assert main(args) == 0  # again: the finished run is no one's, the claimed one still held
    assert "ppo-s0 is training" in caplog.text and "ppo-s1" not in caplog.text
    status = write_status(load_campaign(spec), out)  # as the evaluate stage writes it
    assert {r: s["state"] for r, s in status["runs"].items()} == {
        "ppo-s0": "training",
        "ppo-s1": "done",
    }
