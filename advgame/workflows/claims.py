"""Which process trains a campaign's run: a claim file beside it, so no two processes train one.

A campaign's train stage may be started again while an earlier one still trains (a second
terminal, a session that does not know what the last one left running); both would then write
the same ``runs/RUN`` and rebuild it from its parked copy under each other. So the train stage
claims each run it trains (`claimed`): ``runs/RUN.claim.json`` (in ``runs/``, which git ignores)
holds the process id, the host and the time, created only if absent. A run that a live process
on this host claims, or any process on another host, is left to it (`holder`); a claim whose
process has ended (killed, the machine restarted) is stale and taken over. ``status.json`` shows
a claimed run as ``training`` whichever process writes it (the evaluate stage beside the train
stage too).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

__all__ = ["CLAIM_SUFFIX", "claim_path", "claimed", "describe", "holder", "release"]

CLAIM_SUFFIX = ".claim.json"
"""The claim file of run ``RUN`` is ``runs/RUN`` + this."""


def claim_path(out: Path, run: str) -> Path:
    """The claim file of run `run` of the campaign in folder `out`."""
    return Path(out) / "runs" / f"{run}{CLAIM_SUFFIX}"


def _alive(pid: int) -> bool:
    """Whether process `pid` runs on this host."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def holder(out: Path, run: str) -> dict[str, Any] | None:
    """The claim on `run` (``{"pid", "host", "since"}``) of a process that may train it, or None.

    None when there is no claim, or when it is stale: its process on this host has ended, or
    the file is not a claim (half-written by a process killed at that moment). A claim from
    another host counts (its process cannot be checked from here).
    """
    path = claim_path(out, run)
    try:
        data = json.loads(path.read_text())
        pid, host = int(data["pid"]), str(data["host"])
    except (OSError, ValueError, KeyError, TypeError):  # none, or not a claim
        return None
    if host == socket.gethostname() and not _alive(pid):
        return None
    return dict(data)


def describe(claim: dict[str, Any]) -> str:
    """``"pid 123 on host h since 2026-11-30 20:32"``."""
    since = time.strftime("%Y-%m-%d %H:%M", time.localtime(float(claim.get("since", 0))))
    return f"pid {claim['pid']} on host {claim['host']} since {since}"


def _claim(out: Path, run: str) -> bool:
    """Claim `run` for this process; False if another process holds it."""
    path = claim_path(out, run)
    path.parent.mkdir(parents=True, exist_ok=True)
    held = holder(out, run)
    if held is not None:
        return held["pid"] == os.getpid() and held["host"] == socket.gethostname()
    path.unlink(missing_ok=True)  # stale, or none
    mine = {"pid": os.getpid(), "host": socket.gethostname(), "since": time.time()}
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:  # another process claimed it a moment ago
        return False
    with os.fdopen(fd, "w") as f:
        f.write(json.dumps(mine) + "\n")
    return True


@contextlib.contextmanager
def claimed(out: Path, runs: Sequence[str]) -> Iterator[list[str]]:
    """Claim what of `runs` no other process holds, for the block; yield those runs, in order.

    The claims are removed when the block ends, however it ends.
    """
    mine: list[str] = []
    try:
        for run in runs:
            if _claim(Path(out), run):
                mine.append(run)
        yield list(mine)
    finally:
        release(Path(out), mine)


def release(out: Path, runs: Sequence[str]) -> None:
    """Remove this process's claims on `runs` (runs it does not train after all)."""
    for run in runs:
        claim_path(out, run).unlink(missing_ok=True)
