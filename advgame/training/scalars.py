"""A run's TensorBoard scalars as one CSV file: what a finished run keeps of its learners' logs.

A run's ``tb/`` holds one folder per writer (``loop``, ``protagonist_0``, ``adversary_0``, ...)
and in each one event file per process that wrote it. A resumed run trains again from its last
checkpoint, so the steps of an iteration that was interrupted are written twice. `scalar_rows`
reads every file of a writer in the order its events were written and keeps, per tag, the last
attempt: an event at step ``s`` drops the earlier events of its tag at steps ``>= s`` (the rule
of TensorBoard's own purge of orphaned data). `export_scalars` writes the rows as
``learning.csv`` (``writer,tag,step,value``, values to 7 significant digits: TensorBoard stores
them as float32), which a spreadsheet or pandas opens without TensorBoard. A finished campaign
run keeps that file when its ``tb/`` is deleted (`advgame.workflows.campaign.compact`).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

from advgame.core.config import write_atomic

__all__ = ["export_scalars", "scalar_rows"]

HEADER = ("writer", "tag", "step", "value")
"""The columns of ``learning.csv``."""


def _number(value: Any) -> float | None:
    """A summary value's scalar, or None when it is not one (an image, a histogram, text)."""
    if value.HasField("simple_value"):
        return float(value.simple_value)
    if value.HasField("tensor") and value.metadata.plugin_data.plugin_name == "scalars":
        from tensorboard.util import tensor_util

        array = tensor_util.make_ndarray(value.tensor)
        return float(array.reshape(-1)[0]) if array.size == 1 else None
    return None


def _writer_rows(files: list[Path]) -> dict[str, list[tuple[int, float]]]:
    """Each tag's ``(step, value)`` series in one writer's event `files`, the last attempt kept."""
    from tensorboard.backend.event_processing.event_file_loader import LegacyEventFileLoader

    events: list[tuple[float, str, int, float]] = []
    for path in files:
        for event in LegacyEventFileLoader(str(path)).Load():
            for value in event.summary.value:
                number = _number(value)
                if number is not None:
                    events.append((event.wall_time, value.tag, event.step, number))
    events.sort(key=lambda e: e[0])  # stable: ties keep the files' and the records' order
    series: dict[str, list[tuple[int, float]]] = {}
    for _, tag, step, number in events:
        kept = series.setdefault(tag, [])
        while kept and kept[-1][0] >= step:  # a resumed process wrote these steps again
            kept.pop()
        kept.append((int(step), number))
    return series


def scalar_rows(tb: str | Path) -> list[tuple[str, str, int, float]]:
    """Every scalar in the event files under `tb` as ``(writer, tag, step, value)`` rows.

    `writer` is the event files' folder relative to `tb` (``.`` for `tb` itself); rows come
    sorted by writer and tag, each tag's steps increasing. A missing `tb` gives no rows.
    """
    tb = Path(tb)
    if not tb.is_dir():
        return []
    writers: dict[Path, list[Path]] = {}
    for path in sorted(tb.rglob("events.out.tfevents.*")):
        if path.is_file():
            writers.setdefault(path.parent, []).append(path)
    rows: list[tuple[str, str, int, float]] = []
    for folder, files in sorted(writers.items()):
        writer = folder.relative_to(tb).as_posix()
        for tag, points in sorted(_writer_rows(files).items()):
            rows.extend((writer, tag, step, value) for step, value in points)
    return rows


def export_scalars(tb: str | Path, path: str | Path) -> int:
    """Write `tb`'s scalars to the CSV file `path` (atomically); return the number of rows.

    Nothing is written when `tb` holds no scalars.
    """
    rows = scalar_rows(tb)
    if not rows:
        return 0
    out = io.StringIO()
    table = csv.writer(out, lineterminator="\n")
    table.writerow(HEADER)
    table.writerows((w, tag, step, f"{value:.7g}") for w, tag, step, value in rows)
    write_atomic(path, out.getvalue())
    return len(rows)
