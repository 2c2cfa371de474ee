"""The UR10 backend's parts on their own: the supervisor's limit checks against a scripted link,
the skin reading's watchdog and the sample trace (no controller, no ur_rtde)."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.errors import SafetyLimitError, SkinDisconnectedError
from aptkt.robot import Placement, SafetyLimits
from aptkt.robot.ur10.connection import RobotState
from aptkt.robot.ur10.sampling import Sample, Trace, read_skin
from aptkt.robot.ur10.supervisor import Supervisor

LIMITS = SafetyLimits(max_speed=0.05, max_acceleration=0.5, max_normal_force=5.0)
BOX = Placement("box", 0.0, 0.0, 0.0, (-0.1, -0.1, -0.01), (0.1, 0.1, 0.2))


class ScriptedLink:
    """Stands in for the Connection: hands out one controller state per read (8 ms apart)."""

    frequency = 125.0

    def __init__(self, speeds, wrench_z=0.0, pose=(0.0, 0.0, 0.05)):
        self.speeds = list(speeds)
        self.wrench_z, self.pose = wrench_z, np.array([*pose, 0.0, 0.0, 0.0])
        self.t = 0.0
        self.kicks = 0

    def reset_freshness(self) -> None:
        pass

    def read(self) -> RobotState:
        v = self.speeds.pop(0) if len(self.speeds) > 1 else self.speeds[0]
        self.t += 0.008
        return RobotState(
            self.t,
            True,
            self.pose.copy(),
            np.array([v, 0.0, 0.0, 0.0, 0.0, 0.0]),
            np.array([0.0, 0.0, self.wrench_z, 0.0, 0.0, 0.0]),
        )

    def kick(self) -> None:
        self.kicks += 1


def supervisor(link, **kw) -> Supervisor:
    clock = iter(range(0, 10**12, 1_000_000))
    return Supervisor(
        link,
        LIMITS,
        lambda: next(clock),
        Trace(1.0),
        workspace=kw.pop("workspace", None),
        measured_tolerance=1.5,
        max_supervision_hz=1000.0,
    )


def test_speed_within_the_tolerance_passes_and_above_it_stops():
    sup = supervisor(ScriptedLink([0.07]))  # 1.4x the limit: within the 1.5x tolerance
    assert sup.sample().speed[0] == pytest.approx(0.07)
    with pytest.raises(SafetyLimitError, match="measured TCP speed 0.080 m/s"):
        supervisor(ScriptedLink([0.08])).sample()


def test_acceleration_is_measured_over_the_averaging_window():
    # 0 -> 0.04 m/s in one 8 ms period is 5 m/s^2 over one period, but the check averages over
    # at least 30 ms of controller time: a single step to a constant speed stays below 0.75.
    link = ScriptedLink([0.0] * 5 + [0.004] * 10)
    sup = supervisor(link)
    for _ in range(14):
        sup.sample()
    with pytest.raises(SafetyLimitError, match="measured TCP acceleration"):
        steep = supervisor(ScriptedLink([0.0] * 5 + [0.04] * 10))
        for _ in range(14):
            steep.sample()


def test_wrench_uses_the_median_of_three_and_the_box_applies():
    sup = supervisor(ScriptedLink([0.0], wrench_z=-6.0))
    sup.sample()
    sup.sample()  # two readings: not yet a median of three
    with pytest.raises(SafetyLimitError, match="TCP wrench along the normal 6.00 N"):
        sup.sample()
    outside = supervisor(ScriptedLink([0.0], pose=(0.2, 0.0, 0.05)))
    outside.active = BOX
    with pytest.raises(SafetyLimitError, match="left the workspace box of 'box'"):
        outside.sample()
    cell = supervisor(ScriptedLink([0.0]), workspace=((-1.0, -1.0, 0.1), (1.0, 1.0, 1.0)))
    with pytest.raises(SafetyLimitError, match="outside the robot workspace box"):
        cell.sample()  # z = 0.05 is below the cell's floor


def test_retracting_relaxes_force_and_box_but_not_speed():
    sup = supervisor(ScriptedLink([0.0], wrench_z=-6.0, pose=(0.2, 0.0, 0.05)))
    sup.active, sup.retracting = BOX, True
    for _ in range(4):
        sup.sample()
    sup = supervisor(ScriptedLink([0.2]))
    sup.retracting = True
    with pytest.raises(SafetyLimitError, match="speed"):
        sup.sample()


def test_supervise_kicks_the_watchdog_every_cycle_until_done():
    link = ScriptedLink([0.0])
    sup = supervisor(link)
    last = sup.supervise(until=lambda s: s.timestamp >= 0.04, what="a test")
    assert last.timestamp == pytest.approx(0.04) and link.kicks == 4


class Skin:
    def __init__(self, value, updated_ns):
        self.value, self.updated_ns = value, updated_ns

    def __call__(self) -> float:
        return self.value

    def last_update_ns(self) -> int:
        return self.updated_ns


def test_the_skin_reading_is_checked_for_freshness_and_nan():
    assert read_skin(None, 0, 0.5) == 0.0
    assert read_skin(Skin(0.3, 1_000_000_000), 1_400_000_000, 0.5) == 0.3
    with pytest.raises(SkinDisconnectedError, match="no fresh skin data for 0.60 s"):
        read_skin(Skin(0.3, 1_000_000_000), 1_600_000_000, 0.5)
    with pytest.raises(SafetyLimitError, match="non-finite"):
        read_skin(Skin(float("nan"), 0), 0, 0.5)
    assert read_skin(lambda: 0.2, 10**12, 0.5) == 0.2  # a plain callable: no freshness to check


def test_the_trace_windows_samples_and_estimates_the_clock_offset():
    trace = Trace(1.0)
    for k in range(10):
        host = 5_000_000_000 + k * 8_000_000
        controller = 2.0 + k * 0.008
        z = np.zeros(6)
        trace.append(Sample(host, controller, z, z, z, 0.1 * k))
    window = trace.window(5_016_000_000, 5_040_000_000)
    assert window["host_t_ns"].tolist() == [5_016_000_000, 5_024_000_000, 5_032_000_000]
    assert window["tcp_pose"].shape == (3, 6)
    meta = trace.metadata(5_000_000_000, 5_080_000_000)
    assert meta["robot_clock_offset_ns"] == 3_000_000_000  # host - controller, 3 s
    assert len(meta["robot_trace"]["skin_force"]) == 10
    assert trace.metadata(0, 1)["robot_clock_offset_ns"] is None
