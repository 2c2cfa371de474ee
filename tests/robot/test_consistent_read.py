"""One read of the controller's state takes every value from one RTDE packet, although ur_rtde's
receiving thread may replace its packet between two getter calls."""

from __future__ import annotations

import numpy as np

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
