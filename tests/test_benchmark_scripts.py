"""The timing tools in benchmarks/: the calibration, and the fresh-clone timer's parsing."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def benchmarks(monkeypatch: pytest.MonkeyPatch) -> None:
    """The scripts import each other by name, as they do when run from benchmarks/."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))


@pytest.mark.usefixtures("benchmarks")
def test_the_calibration_is_a_positive_time_per_step() -> None:
    calibrate = importlib.import_module("calibrate")
    us = calibrate.step_us(steps=200, repeats=2, warmup=10)
    assert 0 < us < 1e5  # microseconds per step
    assert calibrate.line(us, 200, 2).startswith("calibration: HalfCheetah-v5 raw step ")


@pytest.mark.usefixtures("benchmarks")
def test_the_fresh_clone_timer_times_each_step_of_the_readmes_two_commands(
    capsys: pytest.CaptureFixture[str],
) -> None:
    timer = importlib.import_module("fresh_clone_times")
    first, second = timer.setup_commands((ROOT / "README.md").read_text())
    assert [kind for kind, _ in timer.steps(first)] == ["venv", "install", "demo"]
    kinds = [kind for kind, _ in timer.steps(second)]
    assert kinds[0] == "venv" and kinds[-1] == "tests" and set(kinds[1:-1]) == {"install"}
    assert timer.main(["--dry-run"]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0] == "[1] venv: python3 -m venv .venv" and printed[-1].startswith("[2] tests:")
    with pytest.raises(ValueError, match="no ```bash block"):
        timer.setup_commands("# a README without commands\n")


@pytest.mark.usefixtures("benchmarks")
def test_the_handoff_benchmark_times_both_splits_of_one_array_game() -> None:
    from advgame.core.native_step import native_loop

    if native_loop() is None:
        pytest.skip("bench_handoff needs the compiled loop (numba: the robosuite extra)")
    handoff = importlib.import_module("bench_handoff")
    ratios = handoff.measure(4, rounds=2, steps=3)
    assert len(ratios) == 2 and all(0 < r < 100 for r in ratios)
    import advgame.scenarios.mujoco_batch as batch
    from advgame.core.physics import shared_stepper

    assert batch.shared_stepper is shared_stepper  # the benchmark put the stepper back
