"""The shared exploratory-action executor drives the UR10 like any robot (paper §5.2 sequence).

Each action runs under the controller's RTDE watchdog (0.5 s), fed by the supervision loop
alone: an attempt that failed while the machine kept that feed waiting for more than half the
period is no evidence either way and is repeated on a healthy robot (a loaded ``make test``
once saw the watchdog stop a slide here); a failure without such a stall fails at once."""

from __future__ import annotations

import time

import numpy as np
import pytest
import rtde_control  # noqa: E402,F401 - the test extra installs ur_rtde; a missing one must fail, not skip
from loopback_helpers import PLACEMENT, STIFFNESS, LoopbackSkin, at_rest  # noqa: E402
from timing import FeedStall, MachineProbe, timeout_for, unless_the_feed_stalled  # noqa: E402

from aptkt.actions import ExplorationSettings, ExploratoryAction, Movement, explore  # noqa: E402
from aptkt.errors import ProtectiveStopError, TrialFault  # noqa: E402
from aptkt.robot import SafetyLimits  # noqa: E402

SETTINGS = ExplorationSettings(
    clearance=0.003, lift_height=0.005, thermal_wait=0.2, stamp_wall_clock=False
)


@pytest.fixture(scope="module")
def silence_timeout():
    """The packets come from a Python thread of the test's own process: on a loaded machine it
    falls behind by more than the shipped 0.1 s of silence, and a silent skin is not what
    these tests are about. Four times the lateness measured now (at least 0.4 s)."""
    machine = MachineProbe()
    try:
        time.sleep(1.0)
        return timeout_for(machine.worst())
    finally:
        machine.close()


def undisturbed(feed: FeedStall, check) -> None:
    unless_the_feed_stalled(feed, check, SafetyLimits().watchdog_timeout)


@pytest.fixture
def skin(loopback, silence_timeout):
    source = LoopbackSkin(loopback, silence_timeout_s=silence_timeout)
    source.open()
    yield source
    source.close()


def test_a_press_action_records_the_hold_with_robot_timestamps(healthy_robot, loopback, skin, feed):
    undisturbed(feed, lambda: _press_records_the_hold(healthy_robot(), loopback, skin))


def _press_records_the_hold(robot, loopback, skin) -> None:
    action = ExploratoryAction("P2-short", Movement.PRESS, depth=0.002, hold_time=0.5)
    rec = explore(robot, skin, PLACEMENT, action, settings=SETTINGS)
    assert rec.duration == pytest.approx(0.5, abs=0.02)
    assert (rec.start_ns, rec.stop_ns) == tuple(rec.metadata["window_ns"]) == robot.action_window_ns
    # During the hold the skin feels the 2 mm press below the light contact (0.05 N) on the
    # 200 N/m surface, give or take a control period of approach latency.
    assert rec.cells == tuple(skin.patch.cell_ids) and not rec.silent_cells
    total = rec.grid("force", 100.0).sum(axis=(0, 2))  # all cells and sensors, every 10 ms
    expected = STIFFNESS * 0.002 + 0.05
    np.testing.assert_allclose(total, expected, atol=0.04)
    # The robot side of the same window: its trace, on both clocks.
    trace = rec.metadata["robot_trace"]
    assert rec.metadata["robot"] == "UR10" and rec.metadata["robot_frequency_hz"] == 125.0
    host = np.array(trace["host_t_ns"])
    assert host.min() >= rec.metadata["movement_start_ns"] - 10_000_000
    assert np.array(trace["tcp_pose"])[:, 2].min() == pytest.approx(
        rec.metadata["contact_z"] - 0.002, abs=1e-6
    )
    assert isinstance(rec.metadata["robot_clock_offset_ns"], int)
    # Afterwards the arm is lifted off and at rest.
    state = at_rest(loopback)
    assert state["normal_force"] == 0.0 and not state["moving"]


def test_a_slide_action_is_cropped_to_its_constant_speed_part(healthy_robot, skin, feed):
    undisturbed(feed, lambda: _slide_is_cropped(healthy_robot(), skin))


def _slide_is_cropped(robot, skin) -> None:
    action = ExploratoryAction(
        "S-short", Movement.SLIDE, normal_force=0.2, speed=0.02, slide_time=0.5
    )
    rec = explore(robot, skin, PLACEMENT, action, settings=SETTINGS)
    assert rec.duration == pytest.approx(0.5, abs=0.01)
    trace = rec.metadata["robot_trace"]
    host = np.array(trace["host_t_ns"])
    speed = np.array(trace["tcp_speed"])[:, 0]
    inside = (host >= rec.start_ns + 20_000_000) & (host < rec.stop_ns)
    np.testing.assert_allclose(speed[inside], 0.02, atol=1e-4)  # robot data lag up to a period
    # The skin's total force over the window stays near the requested 0.2 N.
    per_cell_mean = np.array([rec.samples.for_cell(c).force.sum(axis=1).mean() for c in rec.cells])
    assert per_cell_mean.sum() == pytest.approx(0.2, rel=0.15)


def test_a_fault_mid_action_keeps_the_data_recorded_so_far(healthy_robot, loopback, skin, feed):
    undisturbed(feed, lambda: _fault_keeps_the_data(healthy_robot(), loopback, skin))


def _fault_keeps_the_data(robot, loopback, skin) -> None:
    import threading

    action = ExploratoryAction("C1-short", Movement.STATIC_CONTACT, depth=0.002, hold_time=2.0)
    timer = threading.Timer(1.0, loopback.protective_stop)
    timer.start()
    with pytest.raises(TrialFault) as err:
        explore(robot, skin, PLACEMENT, action, settings=SETTINGS)
    timer.cancel()
    assert isinstance(err.value.cause, ProtectiveStopError) and not err.value.complete
    assert err.value.__cause__ is err.value.cause
    partial = err.value.recording
    assert len(partial.samples) > 0 and partial.duration > 0.3
    assert not at_rest(loopback)["moving"]
