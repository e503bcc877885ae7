"""The relay that hands a batched step's shares to helper threads: results, errors, one caller."""

from __future__ import annotations

import os
import threading
import time

import pytest

from advgame.core.relay import Relay


def test_every_job_runs_once_on_its_own_thread_and_run_waits_for_all() -> None:
    relay = Relay(3)
    seen: dict[int, str] = {}

    def job(i: int) -> None:
        time.sleep(0.01 * i)  # the slowest job ends last: run must still wait for it
        seen[i] = threading.current_thread().name

    try:
        for _ in range(3):
            seen.clear()
            assert relay.run([lambda i=i: job(i) for i in (1, 2, 3)], lambda: job(0))
            assert sorted(seen) == [0, 1, 2, 3]
            assert seen[0] == threading.current_thread().name
            assert len({seen[1], seen[2], seen[3]} - {seen[0]}) == 3  # three helper threads
        assert relay.started
    finally:
        relay.close()
    assert not relay.started
    relay.close()  # idempotent


def test_an_error_in_a_helper_or_in_the_callers_share_is_raised_after_all_ended() -> None:
    relay = Relay(2)
    ended: list[str] = []

    def fails() -> None:
        raise ValueError("helper failed")

    def slow() -> None:
        time.sleep(0.02)
        ended.append("slow")

    try:
        with pytest.raises(ValueError, match="helper failed"):
            relay.run([fails, slow], lambda: ended.append("own"))
        assert sorted(ended) == ["own", "slow"]  # the others ran to their end first
        with pytest.raises(KeyError):
            relay.run([slow], lambda: {}["missing"])
        assert relay.run([slow], lambda: None)  # the relay still works after errors
        with pytest.raises(ValueError, match="3 jobs for 2 helper threads"):
            relay.run([slow] * 3, lambda: None)
    finally:
        relay.close()


def test_a_second_caller_while_the_relay_is_busy_is_told_so() -> None:
    relay = Relay(1)
    inside, release = threading.Event(), threading.Event()
    answers: list[bool] = []

    def hold() -> None:
        inside.set()
        release.wait(5)

    caller = threading.Thread(target=lambda: answers.append(relay.run([hold], lambda: None)))
    caller.start()
    try:
        assert inside.wait(5)
        assert relay.run([lambda: None], lambda: None) is False  # nothing run: do it alone
    finally:
        release.set()
        caller.join(5)
        relay.close()
    assert answers == [True]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork only")
@pytest.mark.filterwarnings("ignore:This process .* is multi-threaded:DeprecationWarning")
def test_a_forked_child_makes_its_own_helpers() -> None:
    """A process forked after the helpers started (a pool worker forked from a process that
    stepped a batch) has none of them: its relay makes its own (Python 3.12+ warns of the fork
    of a threaded process; that fork is the point here)."""
    relay = Relay(1)
    out: list[int] = []
    try:
        assert relay.run([lambda: out.append(1)], lambda: None)
        pid = os.fork()
        if pid == 0:  # the child has no helper threads: run must make new ones, not hang
            code = 0
            try:
                got: list[int] = []
                code = 0 if relay.run([lambda: got.append(2)], lambda: None) and got == [2] else 1
            finally:
                os._exit(code)
        _, status = os.waitpid(pid, 0)
        assert os.waitstatus_to_exitcode(status) == 0
    finally:
        relay.close()
    assert out == [1]


def test_an_interrupt_while_waiting_is_raised_only_once_the_helper_has_ended(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Ctrl-C during a step must not leave a helper stepping the simulations behind the caller's
    back: the wait goes on, and the interrupt comes after."""
    relay = Relay(1)
    ended: list[float] = []
    release = threading.Event()

    def slow() -> None:
        release.wait(5)
        ended.append(time.perf_counter())

    polls = [0]
    real_yield = os.sched_yield

    def interrupting_yield() -> None:
        polls[0] += 1
        if polls[0] == 3:
            threading.Timer(0.05, release.set).start()
            raise KeyboardInterrupt
        real_yield()

    monkeypatch.setattr(os, "sched_yield", interrupting_yield)
    try:
        with pytest.raises(KeyboardInterrupt):
            relay.run([slow], lambda: None, spin=10.0)
        raised = time.perf_counter()
        assert ended and ended[0] <= raised  # the helper's job ended before the interrupt
        monkeypatch.setattr(os, "sched_yield", real_yield)
        out: list[int] = []
        assert relay.run([lambda: out.append(1)], lambda: None)  # still in step afterwards
        assert out == [1]
    finally:
        release.set()
        relay.close()
