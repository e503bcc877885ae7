"""`advgame.training.scalars`: a run's TensorBoard scalars as ``learning.csv``."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from advgame.training.scalars import export_scalars, scalar_rows

SummaryWriter = pytest.importorskip("torch.utils.tensorboard").SummaryWriter


def _write(folder: Path, points: list[tuple[str, int, float]], start: float, **kw: bool) -> None:
    """One process's event file: `points` as scalars written at wall times from `start`."""
    writer = SummaryWriter(str(folder))
    for k, (tag, step, value) in enumerate(points):
        writer.add_scalar(tag, value, step, walltime=start + k, **kw)
    writer.close()


def test_a_resumed_writer_keeps_the_last_attempt_of_each_step(tmp_path: Path) -> None:
    tb = tmp_path / "tb"
    learner = tb / "protagonist_0"
    # the first process logs steps 100..400; it is killed and resumes from its checkpoint at step 200
    first = [("train/loss", s, s / 100) for s in (100, 200, 300, 400)]
    _write(learner, [*first, ("time/fps", 400, 9.0)], start=1000.0)
    # the resumed process writes steps 300 and 500 again: newer values, new_style tensors
    again = [("train/loss", 300, -3.0), ("train/loss", 500, -5.0)]
    _write(learner, again, start=2000.0, new_style=True)
    _write(tb / "loop", [("loop/return", 1, 10.0), ("loop/return", 2, 20.0)], start=1500.0)
    rows = scalar_rows(tb)
    assert rows == [
        ("loop", "loop/return", 1, 10.0),
        ("loop", "loop/return", 2, 20.0),
        ("protagonist_0", "time/fps", 400, 9.0),  # its tag was not written again
        ("protagonist_0", "train/loss", 100, 1.0),
        ("protagonist_0", "train/loss", 200, 2.0),
        ("protagonist_0", "train/loss", 300, -3.0),  # the resumed value, not 3.0
        ("protagonist_0", "train/loss", 500, -5.0),  # 400 dropped: the resume rewound past it
    ]


def test_export_writes_a_csv_of_the_scalars_and_skips_images(tmp_path: Path) -> None:
    tb = tmp_path / "tb"
    writer = SummaryWriter(str(tb / "adversary_0"))
    writer.add_scalar("train/ent_coef", 0.123456789, 7, walltime=1.0)
    writer.add_image("frame", np.zeros((3, 4, 4), dtype=np.uint8), 7, walltime=2.0)
    writer.close()
    out = tmp_path / "learning.csv"
    assert export_scalars(tb, out) == 1
    with out.open() as f:
        table = list(csv.reader(f))
    assert table == [
        ["writer", "tag", "step", "value"],
        ["adversary_0", "train/ent_coef", "7", "0.1234568"],
    ]


def test_no_scalars_write_no_file(tmp_path: Path) -> None:
    out = tmp_path / "learning.csv"
    assert export_scalars(tmp_path / "missing", out) == 0
    (tmp_path / "empty").mkdir()
    assert export_scalars(tmp_path / "empty", out) == 0
    damaged = tmp_path / "damaged" / "protagonist_0"  # not an event file: read as no records
    damaged.mkdir(parents=True)
    (damaged / "events.out.tfevents.1.host.1.1").write_bytes(bytes(range(256)) * 2)
    assert export_scalars(tmp_path / "damaged", out) == 0
    assert not out.exists()
