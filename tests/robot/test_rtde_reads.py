"""Reading the controller through ur_rtde's receive client: one read of its state takes every
value from one RTDE packet, although ur_rtde's receiving thread may replace its packet between
two getter calls; its rate is told from its timestamps however many packets a slow host
misses."""

from __future__ import annotations

import time

import numpy as np
import pytest

from aptkt.errors import RobotConnectionError
from aptkt.robot.ur10.connection import Connection


class _Receive:
    """A receive client whose packet advances (timestamp and pose together, one control period
    and 0.08 mm down) after the getter calls listed in ``advance_after``."""

    def __init__(self, advance_after: set[int]):
        self.packet = 0
        self.calls = 0
        self.advance_after = advance_after

    def _get(self, value):
        self.calls += 1
        if self.calls in self.advance_after:
            self.packet += 1
        return value

    def getTimestamp(self) -> float:  # noqa: N802 - ur_rtde's name
        return self._get(self.packet * 0.008)

    def getActualTCPPose(self) -> list[float]:  # noqa: N802
        return self._get([0.0, 0.0, -0.00008 * self.packet, 0.0, 0.0, 0.0])

    def getActualTCPSpeed(self) -> list[float]:  # noqa: N802
        return self._get([0.0, 0.0, -0.01, 0.0, 0.0, 0.0])

    def getActualTCPForce(self) -> list[float]:  # noqa: N802
        return self._get([0.0] * 6)


def _read(advance_after: set[int]) -> tuple[float, np.ndarray]:
    link = Connection("127.0.0.1", watchdog_timeout=0.5)
    link.receive = _Receive(advance_after)
    ts, pose, _, _ = link._consistent_state()
    return ts, pose


def test_a_packet_that_arrives_between_the_reads_is_read_whole():
    # A new packet lands right after the timestamp was read (call 1): its pose would belong to
    # the next control period.
    ts, pose = _read({1})
    assert pose[2] == -0.00008 * round(ts / 0.008)
    assert ts == 0.008


def test_without_a_new_packet_the_first_reads_stand():
    ts, pose = _read(set())
    assert ts == 0.0 and pose[2] == 0.0


def test_packets_arriving_during_the_retries_too_are_read_whole():
    ts, pose = _read({1, 5})
    assert ts == 0.016 and pose[2] == -0.00008 * 2


def test_a_packet_between_every_two_reads_ends_the_tries_all_the_same():
    link = Connection("127.0.0.1", watchdog_timeout=0.5)
    link.receive = _Receive(set(range(1, 1000)))
    link._consistent_state()
    assert link.receive.calls <= 1 + 4 * 3  # a bounded number of tries, never a hang


class _Stamps:
    """A receive client whose timestamps are read in the given order (the last one repeats)."""

    def __init__(self, stamps: list[float]):
        self.stamps = stamps
        self.calls = 0

    def getTimestamp(self) -> float:  # noqa: N802
        self.calls += 1
        return self.stamps[min(self.calls, len(self.stamps)) - 1]


def _rate(stamps: list[float]) -> float:
    link = Connection("127.0.0.1", watchdog_timeout=0.5)
    link.receive = _Stamps(stamps)
    return link._detect_frequency()


def test_a_cb3_is_125_hz():
    assert _rate([0.008 * k for k in range(40)]) == 125.0


def test_an_e_series_read_on_time_is_500_hz():
    assert _rate([0.002 * k for k in range(40)]) == 500.0


def test_an_e_series_read_by_a_slow_host_is_500_hz():
    # Every read misses packets: 4 of them (8 ms, as a CB3's) at a time, once 3 (6 ms).
    stamps = [0.008 * k for k in range(6)]
    stamps += [stamps[-1] + 0.006 + 0.008 * k for k in range(6)]
    assert _rate(stamps) == 500.0


def test_a_controller_sending_nothing_is_a_lost_link():
    with pytest.raises(RobotConnectionError, match="sends no data"):
        _rate([1.0])


class _Behind(_Receive):
    """A receive client whose packet stays the one read before this process was kept away,
    for the first ``behind`` timestamp reads after it, as a receiving thread that has not yet
    run since; then it is the controller's newest (``behind=None``: never: a lost link)."""

    def __init__(self, behind: int | None):
        super().__init__(set())
        self.behind = behind
        self.stamp_reads = 0

    def getTimestamp(self) -> float:  # noqa: N802
        self.stamp_reads += 1
        if self.behind is not None and self.stamp_reads > self.behind:
            self.packet = 100
        return super().getTimestamp()

    def isConnected(self) -> bool:  # noqa: N802
        return True

    def isProtectiveStopped(self) -> bool:  # noqa: N802
        return False

    def isEmergencyStopped(self) -> bool:  # noqa: N802
        return False

    def getRuntimeState(self) -> int:  # noqa: N802
        return 2  # playing


class _Control:
    connected, ended = True, False

    def kill(self) -> None:
        self.ended = True


def _away(behind: int | None) -> Connection:
    """A link that last saw fresh data (packet 0) a second ago, twice its watchdog: this process
    did not run, or did not look, meanwhile."""
    link = Connection("127.0.0.1", watchdog_timeout=0.5)
    link.receive, link.control = _Behind(behind), _Control()
    link.last_ts, link.last_fresh = 0.0, time.monotonic() - 1.0
    return link


@pytest.mark.parametrize("behind", [1, 3, 10])
def test_data_that_only_looks_old_after_this_process_was_away_is_no_lost_link(behind):
    """After a stall of this process, ur_rtde's receiving thread (in this process too) may not
    yet have read the packets that arrived meanwhile: the first look shows the packet from
    before. It catches up as soon as it runs; the link is lost only if a second look, for a few
    of the controller's periods, shows nothing newer."""
    link = _away(behind)
    state = link.read()
    assert state.fresh and state.timestamp == 0.8 and link.lost is None
    assert _away(behind).link_ok()


def test_data_that_stays_old_is_a_lost_link_after_the_second_look():
    link = _away(None)
    with pytest.raises(RobotConnectionError, match="no fresh robot data for 1.0"):
        link.read()
    assert link.lost is not None
    assert link.receive.stamp_reads > 2  # it looked again (until its deadline) before saying so
    assert not _away(None).link_ok()


class _AnsweringControl:
    """A control process that answers every request at once."""

    ended = False

    def request(self, name: str, *args: object) -> int:
        return 1

    def reply(self, timeout: float, want: int | None = None) -> str:
        return "done"

    def close(self, timeout: float) -> None: ...

    def kill(self) -> None: ...

    def release(self) -> None: ...


def test_a_signal_between_taking_the_call_lock_and_its_try_does_not_hang_the_teardown():
    """Ctrl-C raises in the main thread wherever it is, also right after ``call()`` took the
    lock and before the ``try`` that releases it: the lock stays taken. That thread's stop and
    teardown must still go through (it once hung there for good); another thread stays out."""
    import threading

    link = Connection("127.0.0.1", watchdog_timeout=0.5)
    link.control = _AnsweringControl()  # type: ignore[assignment]
    outcome: list[object] = []
    other_thread_kept_out: list[bool] = []

    def interrupted_then_closing() -> None:
        link._calls.acquire()  # what the interrupted call leaves behind
        probe = threading.Thread(
            target=lambda: other_thread_kept_out.append(not link._calls.acquire(timeout=0.05))
        )
        probe.start()
        probe.join()
        outcome.append(link.call("stopScript"))
        link.drop_clients()
        outcome.append(link.control)

    worker = threading.Thread(target=interrupted_then_closing, daemon=True)
    worker.start()
    worker.join(timeout=10.0)
    assert not worker.is_alive(), "the teardown waited for a lock its own thread held"
    assert outcome == ["done", None]
    assert other_thread_kept_out == [True]
