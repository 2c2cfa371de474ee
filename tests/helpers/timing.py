"""How late this machine runs what asks to run on time, measured while a test runs: the margin
of every assertion that depends on timing.

A test against the loopback controller runs on wall-clock time (ur_rtde's timeouts, the skin's
silence timeout, the arm's motions), on a machine that may be running anything else. A fixed
margin is either loose enough to hide a fault or tight enough to fail some CI run whose load
average is high. So the margin is measured: :class:`LatenessProbe` asks to run every few
milliseconds, does a little work each time (a thread that only sleeps is woken promptly even
on a loaded machine; one that computes waits for its share of a core and of the GIL, as
aptkt's own threads do), and keeps how late each run came. The loopback's control cycle
measures its own lateness the same way (``Loopback.clock_lag``).
"""

from __future__ import annotations

import bisect
import math
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import Protocol

__all__ = [
    "FeedStall",
    "LatenessProbe",
    "MachineProbe",
    "repeat_if_disturbed",
    "timeout_for",
    "wait_for",
]


class _Lagging(Protocol):
    def clock_lag(self) -> float: ...


def timeout_for(lateness: float) -> float:
    """A timeout (a skin's silence, a robot's watchdog) that this machine's measured
    ``lateness`` does not reach: four times it, at least 0.4 s, at most 3 s, in tenths."""
    return min(3.0, max(0.4, math.ceil(4 * lateness * 10) / 10))


class LatenessProbe:
    """A daemon thread running every ``period`` s for ``work`` s of computation, recording the
    lateness of each run (how long after its scheduled time it started). With
    ``catch_up`` it keeps its schedule however late it runs (up to that many seconds behind):
    its lateness then also says how far behind a process that needs ``work / period`` of a
    core falls on this machine, as the loopback's control cycle and aptkt's supervision do;
    without, each run is scheduled from the last, and its lateness is the wake-up's."""

    def __init__(self, period: float = 0.005, work: float = 0.0002, catch_up: float = 0.0):
        self.period, self.work, self.catch_up = period, work, catch_up
        self._times: list[float] = []
        self._late: list[float] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lateness-probe", daemon=True)

    def start(self) -> LatenessProbe:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def _run(self) -> None:
        due = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            with self._lock:
                self._times.append(now)
                self._late.append(max(0.0, now - due))
            end = now + self.work
            while time.monotonic() < end:  # (the work: a thread that needs the GIL and a core)
                pass
            due += self.period
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif -delay > self.catch_up:
                due = time.monotonic()  # late: counted once, not again for every missed period

    def worst(self, since: float, until: float | None = None) -> float:
        """The largest lateness between ``since`` and ``until`` (``time.monotonic()`` values;
        until now by default), and at least the lateness of a run that is overdue now."""
        with self._lock:
            i = bisect.bisect_left(self._times, since)
            j = len(self._times) if until is None else bisect.bisect_right(self._times, until)
            worst = max(self._late[i:j], default=0.0)
            last = self._times[-1] if self._times else since
        overdue = time.monotonic() - last - self.period - self.work if until is None else 0.0
        return max(worst, overdue)


_WATCH = """
import sys, time
sys.path.insert(0, sys.argv[1])
from timing import LatenessProbe
# A fifth of a core, kept to its schedule: about what aptkt's supervision of a motion needs.
probe = LatenessProbe(period=0.005, work=0.001, catch_up=2.0).start()
since = time.monotonic()
while sys.stdin.readline():  # one line per question: the worst lateness since the last one
    now = time.monotonic()
    print(probe.worst(since), flush=True)
    since = now
"""


class MachineProbe:
    """A :class:`LatenessProbe` in a process of its own: how far behind this machine lets a
    process fall that needs a fifth of a core on time, apart from anything the test's own
    process does (a library holding the GIL, say). :meth:`worst` answers for the time since
    the previous answer."""

    def __init__(self) -> None:
        self._proc = subprocess.Popen(
            [sys.executable, "-c", _WATCH, str(__file__).rsplit("/", 1)[0]],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self.worst()  # (its start-up is no lateness of the machine)

    def worst(self) -> float:
        assert self._proc.stdin is not None and self._proc.stdout is not None
        self._proc.stdin.write("?\n")
        self._proc.stdin.flush()
        return float(self._proc.stdout.readline())

    def close(self) -> None:
        if self._proc.stdin is not None:
            self._proc.stdin.close()
        self._proc.wait(timeout=10)


class FeedStall:
    """How long this machine may have kept a controller's watchdog waiting for its feed since
    :meth:`begin`. A kick crosses three processes — aptkt's supervision, its control client and
    the controller — and each can be kept waiting in turn: the loopback's control cycle says
    how late the controller ran (``clock_lag()``), a :class:`MachineProbe` how late any other
    process did, and the delays along the way add up."""

    def __init__(self, loopback: _Lagging, machine: MachineProbe):
        self.loopback, self.machine = loopback, machine
        self.loop_lag = self.machine_late = 0.0

    def begin(self) -> None:
        self.loopback.clock_lag()
        self.machine.worst()
        self.loop_lag = self.machine_late = 0.0

    def measure(self) -> None:
        """Take in the lateness since the last measurement (the probes forget on reading)."""
        self.loop_lag = max(self.loop_lag, self.loopback.clock_lag())
        self.machine_late = max(self.machine_late, self.machine.worst())

    def stall(self) -> float:
        self.measure()
        return self.loop_lag + 2 * self.machine_late


def wait_for(condition: Callable[[], bool], timeout: float, poll: float = 0.01) -> bool:
    """Poll ``condition`` until it holds (True) or ``timeout`` s have passed (False): a state
    that comes after a delay is waited for, not assumed after a fixed sleep."""
    deadline = time.monotonic() + timeout
    while True:
        if condition():
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(poll)


def repeat_if_disturbed(
    attempt: Callable[[], object],
    check: Callable[[object], None],
    *,
    stall: Callable[[], float],
    budget: float,
    begin: Callable[[], None] = lambda: None,
    restore: Callable[[], None] = lambda: None,
    attempts: int = 4,
) -> None:
    """``check(attempt())``; again (after ``restore()``) if the check failed while ``stall()``
    — the lateness measured since ``begin()`` — exceeded ``budget``: then a timeout may have
    fired that a machine keeping to time would not have reached, and the run is no evidence
    either way. A failure without such a stall fails at once, as does the last attempt."""
    for k in range(1, attempts + 1):
        begin()
        result = attempt()
        try:
            check(result)
            return
        except Exception as exc:  # (an assertion, or a file the check reads missing)
            late = stall()
            if late <= budget or k == attempts:
                # (What was measured, for whoever reads the failure: a fault of the code, or
                # a delay no probe saw.)
                exc.add_note(f"attempt {k}: kept waiting {late:.3f} s; budget {budget:.3f} s")
                raise
            print(
                f"attempt {k} disturbed: kept waiting {late:.2f} s, more than {budget:.2f} s; again"
            )
        restore()


def unless_the_feed_stalled(feed: FeedStall, check: Callable[[], None], watchdog: float) -> None:
    """``check()`` (a movement under the controller's watchdog of period ``watchdog``, and what
    it must do), repeated if it failed while ``feed`` says the watchdog was kept waiting for
    more than half the period (:func:`repeat_if_disturbed`)."""
    repeat_if_disturbed(
        lambda: None,
        lambda _: check(),
        begin=feed.begin,
        stall=feed.stall,
        budget=watchdog / 2,
    )
