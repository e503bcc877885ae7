"""Progress of long runs: timed lines in log files, bars on terminals, per-unit reports."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from advgame.core.progress import WINDOW, LineProgress, Silent, progress
from advgame.errors import ConfigError
from advgame.runner.run import run_units


class Clock:
    """A settable time source."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_lines_come_at_the_interval_and_at_milestones_with_an_estimate() -> None:
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(1000, "train X", unit="step", interval=60, stream=out, clock=clock)
    clock.now = 30
    bar.update(100)
    assert out.getvalue() == ""  # before the interval: nothing
    clock.now = 60
    bar.update(100)
    (line,) = out.getvalue().splitlines()
    # 200 of 1,000 in 60 s: 800 more at that rate is 240 s
    assert line.endswith("train X: 200/1,000 steps (20 %), 60 s, about 4.0 min left")
    bar.set_postfix_str("iteration 2/10")  # a milestone writes at once, and stays
    assert out.getvalue().splitlines()[-1].endswith("about 4.0 min left; iteration 2/10")
    written = out.getvalue()
    bar.close()  # nothing moved since the last line
    assert out.getvalue() == written
    clock.now = 90
    bar.update(800)
    bar.close()
    assert (
        out.getvalue()
        .splitlines()[-1]
        .endswith("1,000/1,000 steps (100 %), 1.5 min; last: iteration 2/10")
    )  # the closing line is not the milestone's: it says which milestone came last


def test_a_timed_line_after_a_milestone_says_it_is_the_last_one() -> None:
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(1000, "train X", unit="step", interval=60, stream=out, clock=clock)
    clock.now = 10
    bar.set_postfix_str("iteration 1/10 in 10 s", refresh=False)
    bar.update(100)  # the milestone's own line
    clock.now = 80
    bar.update(50)  # mid-iteration, after the interval
    first, second = out.getvalue().splitlines()
    assert first.endswith(
        "100/1,000 steps (10 %), 10 s, about 1.5 min left; iteration 1/10 in 10 s"
    )
    assert "150/1,000 steps (15 %)" in second
    assert second.endswith("; last: iteration 1/10 in 10 s")


def test_the_estimate_follows_the_recent_rate_after_a_pause() -> None:
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(10_100, "x", unit="step", stream=out, clock=clock, interval=1e9)
    clock.now = 3600.0  # stopped for an hour before its first step
    for _ in range(WINDOW):
        clock.now += 10
        bar.update(100)
        bar.set_postfix_str("")
    assert out.getvalue().splitlines()[-1].endswith("about 9.4 h left")  # the pause still counts
    clock.now += 10
    bar.update(100)
    bar.set_postfix_str("")  # the window now starts after the pause: 100 steps per 10 s
    assert out.getvalue().splitlines()[-1].endswith("about 15.0 min left")


def test_a_milestone_with_a_count_is_one_line() -> None:
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(4, "runs", unit="run", stream=out, clock=clock, interval=60)
    clock.now = 3600  # long past the interval, as a unit of hours is
    bar.set_postfix_str("finished: a", refresh=False)
    assert out.getvalue() == ""
    bar.update()
    (line,) = out.getvalue().splitlines()
    assert "runs: 1/4 runs (25 %)" in line and line.endswith("; finished: a")
    bar.update()  # no milestone pending, the interval not passed again: nothing
    assert len(out.getvalue().splitlines()) == 1


def test_no_estimate_where_units_differ_in_size() -> None:
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(5, "campaign x", unit="run", stream=out, clock=clock, estimate=False)
    clock.now = 600
    bar.update()
    bar.set_postfix_str("finished: a")
    assert out.getvalue().rstrip().endswith("campaign x: 1/5 runs (20 %), 10.0 min; finished: a")


def test_counts_done_before_this_process_are_not_in_its_rate() -> None:
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(100, "evaluate", initial=40, stream=out, clock=clock)
    bar.skip(10)  # read back from part files
    clock.now = 100
    bar.update(10)  # 10 units in 100 s: the 40 left take 400 s
    bar.set_postfix_str("")
    assert "60/100 units (60 %), 1.7 min, about 6.7 min left" in out.getvalue()


def test_a_terminal_gets_a_bar_a_file_gets_lines_and_no_show_gets_nothing() -> None:
    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    assert isinstance(progress(10, "x", show=False), Silent)
    assert isinstance(progress(10, "x", stream=io.StringIO()), LineProgress)
    bar = progress(10, "x", stream=Terminal())
    assert not isinstance(bar, LineProgress) and hasattr(bar, "set_postfix_str")
    bar.close()
    assert isinstance(progress(10, "x", stream=Terminal(), lines=True), LineProgress)


class Recorder:
    """A progress object that wants to know which unit finished."""

    def __init__(self) -> None:
        self.events: list[tuple[str, int, bool]] = []

    def units_started(self, count: int) -> None:
        self.events.append(("started", count, False))

    def unit_done(self, index: int, before: bool) -> None:
        self.events.append(("done", index, before))


def test_run_units_names_each_finished_unit_and_those_read_back(tmp_path: Path) -> None:
    rec = Recorder()
    run_units(abs, [-3, -1, -2], parts_dir=tmp_path, progress=rec)
    assert rec.events == [("started", 3, False)] + [("done", i, False) for i in range(3)]
    rec = Recorder()
    run_units(abs, [-3, -5, -1, -2], parts_dir=tmp_path, progress=rec)
    # three read back first (index 0, 2, 3), then one trained
    assert rec.events == [
        ("done", 0, True),
        ("done", 2, True),
        ("done", 3, True),
        ("started", 1, False),
        ("done", 1, False),
    ]
    out = io.StringIO()
    lines = LineProgress(4, "units", stream=out, interval=0)
    run_units(abs, [-3, -5, -1, -2], parts_dir=tmp_path, progress=lines)
    assert lines.n == lines.initial == 4  # a plain LineProgress counts read-back units as before


def test_run_units_hands_each_record_to_on_unit_as_it_finishes(tmp_path: Path) -> None:
    seen: list[tuple[int, int, int]] = []

    def keep(index: int, rec: object) -> None:
        files = sorted(p.name for p in tmp_path.glob("*.pkl"))
        seen.append((index, rec.value, len(files)))  # type: ignore[attr-defined]

    run_units(abs, [-3, -1], parts_dir=tmp_path, on_unit=keep)
    assert seen == [(0, 3, 1), (1, 1, 2)]  # each after its own part file is written
    seen.clear()
    run_units(abs, [-4, -1, -3], parts_dir=tmp_path, on_unit=keep)
    assert seen == [(1, 1, 2), (2, 3, 2), (0, 4, 3)]  # read back first, then the new one


def test_a_training_run_logs_a_line_per_iteration(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from advgame.training import resume, train
    from tests._training_helpers import PENDULUM, config

    cfg = config("ppo", scenario=PENDULUM, iterations=2)
    with pytest.raises(ConfigError, match="progress must be True, False or 'lines'"):
        train(cfg, tmp_path / "bad", progress="bars")
    train(cfg, tmp_path / "run", progress=True)  # stderr is not a terminal here: lines
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if "train InvertedPendulum-v5 run:" in ln]
    assert len(lines) == 2, err
    assert "iteration 1/2 in " in lines[0] and "protagonist return" in lines[0]
    assert "256/256 steps (100 %)" in lines[1] and "iteration 2/2" in lines[1]
    # a resumed run counts what was done before (nothing left here: no iteration line)
    resume(tmp_path / "run", progress=False)
    assert "train InvertedPendulum-v5" not in capsys.readouterr().err


def test_the_search_counts_a_candidates_reported_steps_once() -> None:
    """A candidate trained here reports its pieces; its end adds only what was not reported
    (all of it from a pool worker, the steps before its save for a resumed one)."""
    from types import SimpleNamespace

    from advgame.core.progress import listening, report
    from advgame.evaluation.attacks.optimal import _CandidateProgress

    counted: list[tuple[str, int]] = []
    bar = SimpleNamespace(
        update=lambda n: counted.append(("update", n)),
        skip=lambda n: counted.append(("skip", n)),
        set_postfix_str=lambda text, refresh=True: None,
        close=lambda: None,
    )
    units = [SimpleNamespace(steps=s, name=f"a/{i}") for i, s in enumerate((100, 50, 80))]
    shown = _CandidateProgress(units, "X", False)
    shown.bar = bar
    shown.unit_done(1, True)  # read back
    with listening(shown.step):
        report(60)
        report(40)
        shown.unit_done(0, False)
        report(20)  # a resumed candidate: 60 of its 80 steps were trained before its save
        shown.unit_done(2, False)
    report(99)  # no one listens any more
    shown.unit_done(0, False)  # as from a pool worker: nothing reported, all counted at its end
    updates = [n for kind, n in counted if kind == "update"]
    assert sum(updates) == 100 + 20 + 100  # this process's work, in the rate
    assert [n for kind, n in counted if kind == "skip"] == [50, 60]  # read back; before a save
