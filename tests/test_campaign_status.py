"""The training curves of a campaign while it trains: every copy of a run counts, the furthest wins."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from advgame.cli import main
from advgame.reports.plots import method_series
from advgame.workflows.campaign import load_campaign
from advgame.workflows.campaign_status import (
    progress_curves,
    progress_files,
    seconds_left,
    write_status,
)

SPEC = """
scenario = "Hopper-v5"
methods = ["sac", "ompo"]
seeds = [0, 1, 2]

[train]
iterations = 30
protagonist_steps = 10000
eval_episodes = 0
"""

COLUMNS = ["protagonist_steps", "protagonist_phase_true_return", "wall_s"]


def _progress(
    folder: Path, returns: list[float], iteration: int | None = None, wall: float = 100.0
) -> None:
    """A run folder with a progress CSV of `returns`, one row per iteration (`wall` + i s each)."""
    folder.mkdir(parents=True)
    rows = [",".join(COLUMNS)]
    rows += [f"{10000 * (i + 1)},{r},{wall + i}" for i, r in enumerate(returns)]
    (folder / "progress.csv").write_text("\n".join(rows) + "\n")
    n = len(returns) if iteration is None else iteration
    (folder / "state.json").write_text(json.dumps({"iteration": n}))


def test_method_series_cuts_to_the_shortest_run_or_pads_to_the_longest(tmp_path: Path) -> None:
    _progress(tmp_path / "a", [1.0, 2.0, 3.0])
    _progress(tmp_path / "b", [5.0, 6.0])
    groups = {"m": [tmp_path / "a" / "progress.csv", tmp_path / "b" / "progress.csv"]}

    cut = method_series(groups, ["protagonist_phase_true_return"])["m"]
    np.testing.assert_array_equal(cut["protagonist_phase_true_return"], [[1, 2], [5, 6]])

    ragged = method_series(groups, ["protagonist_phase_true_return"], ragged=True)["m"]
    np.testing.assert_array_equal(
        ragged["protagonist_phase_true_return"], [[1, 2, 3], [5, 6, np.nan]]
    )
    np.testing.assert_array_equal(np.nanmax(ragged["protagonist_steps"], axis=0), [1e4, 2e4, 3e4])
    # the mean at each point is over the runs that have reached it
    np.testing.assert_array_equal(
        np.nanmean(ragged["protagonist_phase_true_return"], axis=0), [3, 4, 3]
    )


def test_the_curves_numbers_are_written_beside_the_figure(tmp_path: Path) -> None:
    import csv

    from advgame.reports.plots import plot_method_curves

    _progress(tmp_path / "a", [1.0, 2.0, 3.0])
    _progress(tmp_path / "b", [5.0, 6.0])
    groups = {"m": [tmp_path / "a" / "progress.csv", tmp_path / "b" / "progress.csv"]}
    figure = plot_method_curves(
        groups, tmp_path / "fig.png", ["protagonist_phase_true_return"], ragged=True
    )
    assert figure is not None and figure.is_file()
    with (tmp_path / "fig.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["protagonist_steps"] for r in rows] == ["10000", "20000", "30000"]
    assert [int(r["runs"]) for r in rows] == [2, 2, 1]
    assert [float(r["protagonist_phase_true_return_mean"]) for r in rows] == [3, 4, 3]
    assert [float(r["protagonist_phase_true_return_min"]) for r in rows] == [1, 2, 3]
    assert [float(r["protagonist_phase_true_return_max"]) for r in rows] == [5, 6, 3]
    assert {r["method"] for r in rows} == {"m"}


def test_a_method_with_no_run_yet_is_no_warning_but_a_run_without_the_column_is(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    pending = {"m": [tmp_path / "none" / "progress.csv"]}  # a campaign's method not trained yet
    with caplog.at_level("WARNING", logger="advgame.reports.plots"):
        assert method_series(pending, ["protagonist_phase_true_return"]) == {}
    assert caplog.records == []
    _progress(tmp_path / "a", [1.0])
    with caplog.at_level("WARNING", logger="advgame.reports.plots"):
        assert method_series({"m": [tmp_path / "a" / "progress.csv"]}, ["cost"]) == {}
    assert "no progress CSV of 'm' has" in caplog.text


def test_each_run_is_read_from_its_furthest_copy(tmp_path: Path) -> None:
    spec = tmp_path / "grid.toml"
    spec.write_text(SPEC)
    campaign = load_campaign(spec)
    out = tmp_path / "grid"
    _progress(out / "finished" / "sac-s0", [float(i) for i in range(30)])
    _progress(out / "runs" / "ompo-s0", [1.0, 2.0, 3.0])  # runs/ behind its parked copy
    _progress(out / "parked" / "ompo-s0", [1.0, 2.0, 3.0, 4.0, 5.0])
    _progress(out / "runs" / "ompo-s1", [7.0, 8.0])  # in training, never parked
    (out / "runs" / "ompo-s2").mkdir(parents=True)  # started, no iteration yet

    files = progress_files(campaign, out)
    assert files == {
        "sac-s0": out / "finished" / "sac-s0" / "progress.csv",
        "ompo-s0": out / "parked" / "ompo-s0" / "progress.csv",
        "ompo-s1": out / "runs" / "ompo-s1" / "progress.csv",
    }
    path = progress_curves(campaign, out)
    assert path == out / "progress.png" and path.stat().st_size > 1000


def test_status_draws_the_curves_so_far_or_says_nothing_has_trained(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = tmp_path / "grid.toml"
    spec.write_text(SPEC)
    out = tmp_path / "grid"
    assert main(["campaign", str(spec), "--status"]) == 0
    text = capsys.readouterr().out
    assert "training curves: nothing to draw yet" in text
    assert "training left: 6 run(s), none with a measured rate yet" in text
    assert not (out / "progress.png").exists()

    _progress(out / "parked" / "ompo-s1", [1.0, 2.0], iteration=2, wall=900.0)
    assert main(["campaign", str(spec), "--status"]) == 0
    text = capsys.readouterr().out
    assert "ompo-s1: partial (2/30), about 7.0 h left" in text  # 28 iterations of 900.5 s
    assert "ompo-s0: pending (0/30), about 7.5 h left" in text  # 30 at its method's rate
    assert "training left: about 22.0 worker-hours for 3 run(s)" in text
    assert "3 run(s) without a measured rate" in text  # SAC's: none of them has trained
    assert f"training curves so far: {out / 'progress.png'}" in text
    assert (out / "progress.png").is_file()


def test_time_left_is_each_run_s_recent_rate_or_its_method_s(tmp_path: Path) -> None:
    spec = tmp_path / "grid.toml"
    spec.write_text(SPEC)
    campaign = load_campaign(spec)
    out = tmp_path / "grid"
    _progress(out / "finished" / "sac-s0", [0.0] * 30, wall=10.0)  # 10, 11, ..., 39 s
    _progress(out / "parked" / "ompo-s0", [0.0] * 5, wall=600.0)  # 600, ..., 604 s
    _progress(out / "runs" / "ompo-s1", [0.0] * 2, wall=900.0)  # 900, 901 s

    left = seconds_left(campaign, out, write_status(campaign, out))
    assert "sac-s0" not in left  # finished
    assert left["sac-s1"] == left["sac-s2"] == pytest.approx(38.0 * 30)  # sac-s0's last three
    assert left["ompo-s0"] == pytest.approx(603.0 * 25)  # its last three: 602, 603, 604
    assert left["ompo-s1"] == pytest.approx(900.5 * 28)
    assert left["ompo-s2"] == pytest.approx((603.0 + 900.5) / 2 * 30)  # its method's runs

    spec.write_text(SPEC.replace('methods = ["sac", "ompo"]', 'methods = ["sac", "ompo", "dbc"]'))
    campaign = load_campaign(spec)
    left = seconds_left(campaign, out, write_status(campaign, out))
    assert left["dbc-s0"] is None  # no run of its method has trained


def test_a_damaged_wall_time_is_no_rate_rather_than_a_traceback(tmp_path: Path) -> None:
    spec = tmp_path / "grid.toml"
    spec.write_text(SPEC)
    campaign = load_campaign(spec)
    out = tmp_path / "grid"
    (out / "runs" / "sac-s0").mkdir(parents=True)
    (out / "runs" / "sac-s0" / "progress.csv").write_text("iteration,wall_s\n1,abc\n2,\n")
    left = seconds_left(campaign, out, write_status(campaign, out))
    assert left["sac-s0"] is None and left["ompo-s0"] is None
