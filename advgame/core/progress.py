"""Progress of long runs: a tqdm bar on a terminal, plain timed lines in a log file.

A campaign left running for hours under ``nohup`` or ``setsid ... > log 2>&1`` writes to a
file, where a bar is either silent or a single line of carriage returns. `progress` gives a
tqdm bar when the stream is a terminal and a `LineProgress` otherwise: one line with the
time, the count, the share done, the elapsed time and an estimate of what is left, at most every
`LineProgress.interval` seconds and whenever a caller marks a milestone (`set_postfix_str`,
e.g. an iteration or a unit finished); lines between milestones repeat the last one as
``last: ...``, so a count in the middle of an iteration does not read as that iteration's end.
Both have tqdm's ``update``, ``set_postfix_str`` and ``close``, so callers drive either the same
way; as with tqdm, a milestone that comes with a count is ``set_postfix_str(text,
refresh=False)`` then ``update(n)``: one line, with both.
"""

from __future__ import annotations

import sys
import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import IO, Any

__all__ = ["WINDOW", "LineProgress", "Silent", "count_before", "listening", "progress", "report"]

WINDOW = 10
"""Lines over which `LineProgress` measures the rate behind its estimate of the time left."""


class Silent:
    """Progress that shows nothing (``show=False``)."""

    def update(self, n: int = 1) -> None:
        """Nothing to show."""

    def set_postfix_str(self, text: str = "", refresh: bool = True) -> None:
        """Nothing to show."""

    def close(self) -> None:
        """Nothing to close."""


def _duration(seconds: float) -> str:
    """``"42 s"``, ``"7.5 min"`` or ``"3.2 h"``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 90 * 60:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


class LineProgress:
    """Progress as timed lines, for logs.

    Args:
        total: the count at the end.
        desc: what is counted, at the start of each line (``"train Hopper-v5 ppo-s0"``).
        unit: the counted thing, singular (``"step"``, ``"candidate"``).
        initial: the count already done before this process (a resumed run); the estimate of
            what is left uses only the rate of this process.
        interval: seconds between two lines written by `update` alone.
        stream: where lines go (default ``sys.stderr``).
        clock: the time source (seconds; for tests).
        estimate: add the estimate of what is left (False where units differ widely in size,
            such as a campaign's runs, some of them resumed).

    """

    def __init__(
        self,
        total: int,
        desc: str,
        *,
        unit: str = "unit",
        initial: int = 0,
        interval: float = 300.0,
        stream: IO[str] | None = None,
        clock: Any = time.monotonic,
        estimate: bool = True,
    ) -> None:
        self.total, self.desc, self.unit = int(total), desc, unit
        self.estimate = estimate
        self.n = self.initial = int(initial)
        self.interval = float(interval)
        self.stream = stream
        self.clock = clock
        self.start = self.last = clock()
        self.postfix = ""
        self.pending = False
        """A milestone not written yet: the next line is its own (with ``refresh=False``, the next
        `update` writes it); lines after it show it as ``last: ...``."""
        self.written = self.n
        self.marks: deque[tuple[float, int]] = deque([(self.start, self.n)], maxlen=WINDOW)
        """(time, count) at the last lines: the estimate uses the rate since the oldest, so a
        pause (a process stopped for a while) leaves it after `WINDOW` lines."""

    def update(self, n: int = 1) -> None:
        """Count `n` more; write a line for a pending milestone or after `interval` seconds."""
        self.n += n
        if self.pending or self.clock() - self.last >= self.interval:
            self.write()

    def skip(self, n: int) -> None:
        """Count `n` as done before this process (like `initial`: not in the rate)."""
        self.n += n
        self.initial += n
        self.written = self.n
        self.marks = deque(((t, c + n) for t, c in self.marks), maxlen=WINDOW)

    def set_postfix_str(self, text: str = "", refresh: bool = True) -> None:
        """Mark a milestone: `text` ends its line, and later lines as ``last: text``.

        A line is written now, or with ``refresh=False`` at the next `update` (tqdm's
        signature: a milestone that comes with a count is then one line).
        """
        self.postfix = text
        self.pending = True
        if refresh:
            self.write()

    def close(self) -> None:
        """Write a last line if the count moved since the previous one."""
        if self.n != self.written:
            self.write()

    def line(self) -> str:
        """The line `write` would write now (without the time stamp)."""
        now = self.clock()
        elapsed = now - self.start
        share = f" ({100 * self.n / self.total:.0f} %)" if self.total > 0 else ""
        text = f"{self.desc}: {self.n:,}/{self.total:,} {self.unit}s{share}, {_duration(elapsed)}"
        since, count = self.marks[0]
        if self.estimate and count < self.n < self.total:
            left = (self.total - self.n) * (now - since) / (self.n - count)
            text += f", about {_duration(left)} left"
        if not self.postfix:
            return text
        return f"{text}; {self.postfix}" if self.pending else f"{text}; last: {self.postfix}"

    def write(self) -> None:
        """Write the current line, time-stamped, and flush."""
        stream = self.stream if self.stream is not None else sys.stderr
        stamp = time.strftime("%H:%M:%S")
        print(f"[{stamp}] {self.line()}", file=stream, flush=True)
        self.last, self.written, self.pending = self.clock(), self.n, False
        self.marks.append((self.last, self.n))


def count_before(bar: Any, n: int) -> None:
    """Count `n` done before this process on any display `progress` gives.

    A `LineProgress` keeps them out of its rate (`LineProgress.skip`); a tqdm bar or `Silent`
    just counts them.
    """
    getattr(bar, "skip", bar.update)(n)


def progress(
    total: int,
    desc: str,
    *,
    unit: str = "unit",
    initial: int = 0,
    show: bool = True,
    lines: bool | None = None,
    stream: IO[str] | None = None,
) -> Any:
    """A progress display with ``update``, ``set_postfix_str`` and ``close``.

    Args:
        total: the count at the end.
        desc: what is counted.
        unit: the counted thing, singular.
        initial: the count already done (a resumed run).
        show: False: `Silent`.
        lines: True: `LineProgress`; False: a tqdm bar; None: a bar when `stream` is a
            terminal, lines otherwise.
        stream: where it writes (default ``sys.stderr``).

    """
    if not show:
        return Silent()
    out = stream if stream is not None else sys.stderr
    if lines is None:
        lines = not (hasattr(out, "isatty") and out.isatty())
    if lines:
        return LineProgress(total, desc, unit=unit, initial=initial, stream=stream)
    from tqdm.auto import tqdm

    return tqdm(
        total=total,
        initial=initial,
        desc=desc,
        unit=unit,
        smoothing=0.1,
        mininterval=1.0,
        file=out,
    )


_LISTENERS: list[Callable[[int], None]] = []


def report(n: int) -> None:
    """Tell this process's listeners that the running job has done `n` more of its units.

    A long job (a best response: its steps) reports as it goes, so that a bar counting such
    jobs moves inside one of them. Nothing listens in a pool worker, whose driver counts the
    job when it ends: reporting costs nothing where no one listens.
    """
    for listener in list(_LISTENERS):
        listener(n)


@contextmanager
def listening(listener: Callable[[int], None]) -> Iterator[None]:
    """Call `listener(n)` for every `report` made inside (jobs run in this process).

    Example:
        >>> seen = []
        >>> with listening(seen.append):
        ...     report(3)
        >>> report(4)
        >>> seen
        [3]

    """
    _LISTENERS.append(listener)
    try:
        yield
    finally:
        _LISTENERS.remove(listener)
