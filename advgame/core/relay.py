"""Persistent helper threads handed one job per batched step, with the cheapest hand-off.

`ThreadedStepper` splits each batched step's envs over the calling thread and ``threads - 1``
helpers. A `concurrent.futures.ThreadPoolExecutor` made each hand-off a `Future` (a new
condition variable), a work item and a queue put, then a sleep on that condition for the
result: about 30 µs to hand the job over and, when the helper finished last, up to 170 µs for
the caller to wake (measured at 64 HalfCheetah copies on two threads, 7 Dec). A `Relay` keeps
one thread per helper, each parked on a plain lock: handing it a job is one lock release and
collecting it one lock acquire (CPython's lock is a semaphore; a blocked acquire releases the
GIL), after a short poll for a helper still at work, so that the caller is not asleep when the
helper ends.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable

__all__ = ["Relay"]


class _Helper:
    """One daemon thread that runs the job it is given, once per `start`."""

    def __init__(self, name: str) -> None:
        self._go = threading.Lock()
        self._go.acquire()
        self._done = threading.Lock()
        self._done.acquire()
        self._job: Callable[[], None] | None = None
        self._error: BaseException | None = None
        self.thread = threading.Thread(target=self._serve, name=name, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while True:
            self._go.acquire()
            job = self._job
            if job is None:  # `stop`
                self._done.release()
                return
            try:
                job()
            except BaseException as error:  # handed to the caller by `wait`
                self._error = error
            self._job = None
            self._done.release()

    def start(self, job: Callable[[], None]) -> None:
        self._job = job
        self._go.release()

    def wait(self, spin: float) -> BaseException | None:
        """Wait for the job to end (polling for `spin` seconds first); return its error.

        An interrupt (KeyboardInterrupt, a signal handler's error) while waiting does not stop
        the wait: the helper may still be stepping the caller's simulations, so it is raised
        once the job has ended.
        """
        interrupt: BaseException | None = None
        end = time.perf_counter() + spin
        while True:
            try:
                if self._done.acquire(blocking=False):
                    break
                if time.perf_counter() > end:
                    self._done.acquire()
                    break
                os.sched_yield()  # poll, giving the core away between polls, then sleep
            except BaseException as caught:
                interrupt = interrupt or caught
        failed, self._error = self._error, None
        if interrupt is not None:
            raise interrupt
        return failed

    def stop(self) -> None:
        self._job = None
        self._go.release()
        self.wait(0.0)
        self.thread.join()


class Relay:
    """`helpers` threads that each run one job per `run` call beside the calling thread.

    One caller at a time: `run` returns ``False`` without running anything when another
    thread is inside it (the caller then does all the work itself), and in a forked child the
    helpers are made anew (a child has only the thread that forked).

    Example:
        >>> relay = Relay(1)
        >>> out = [0, 0]
        >>> relay.run([lambda: out.__setitem__(1, 2)], lambda: out.__setitem__(0, 1))
        True
        >>> out
        [1, 2]
        >>> relay.close()

    """

    def __init__(self, helpers: int, name: str = "advgame-physics") -> None:
        self.size = helpers
        """How many helper threads."""
        self._name = name
        self._helpers: list[_Helper] = []
        self._pid = -1
        self._busy = threading.Lock()

    @property
    def started(self) -> bool:
        """Whether this process's helper threads exist (made by the first `run`)."""
        return self._pid == os.getpid() and bool(self._helpers)

    def run(
        self, jobs: list[Callable[[], None]], own: Callable[[], None], spin: float = 0.0
    ) -> bool:
        """Run ``jobs[i]`` on helper ``i`` and `own` on this thread; return when all are done.

        Returns ``False`` (nothing run) when another thread is running the relay. An error in
        any job is raised here once every job has ended: `own`'s, else the first helper's.

        Args:
            jobs: at most `size` jobs, one per helper.
            own: this thread's job.
            spin: once `own` is done, seconds to poll a helper still at work (yielding the
                core between polls) before sleeping on its lock: a thread asleep takes tens of
                µs to wake on a virtual machine, longer than the last bit of a helper's work.

        """
        if len(jobs) > self.size:
            raise ValueError(f"{len(jobs)} jobs for {self.size} helper threads.")
        if not self._busy.acquire(blocking=False):
            return False
        try:
            if self._pid != os.getpid():  # first use, or a forked child: no helpers yet
                self._pid = os.getpid()
                self._helpers = [_Helper(f"{self._name}-{i}") for i in range(self.size)]
            helpers = self._helpers[: len(jobs)]
            for helper, job in zip(helpers, jobs, strict=True):
                helper.start(job)
            try:
                own()
            finally:  # every helper is collected, whatever `own` raised
                errors, interrupt = [], None
                for helper in helpers:
                    try:
                        errors.append(helper.wait(spin))
                    except BaseException as caught:  # an interrupt: raised once all are in
                        interrupt = interrupt or caught
                if interrupt is not None:
                    raise interrupt
            for failed in errors:
                if failed is not None:
                    raise failed
            return True
        finally:
            self._busy.release()

    def close(self) -> None:
        """Stop the helper threads (idempotent; the next `run` starts them again)."""
        with self._busy:
            if self._pid == os.getpid():
                for helper in self._helpers:
                    helper.stop()
            self._helpers, self._pid = [], -1
