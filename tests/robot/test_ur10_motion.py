"""Every motion primitive of the UR10 backend, through the real ur_rtde client and the loopback.

During a movement only aptkt's supervision feeds the controller's watchdog (0.5 s). A test
whose movement failed while the machine kept that feed waiting for more than half the period
is repeated on a healthy robot and a new skin (``on_a_healthy_arm``); a failure without such a
stall fails at once."""

from __future__ import annotations

import time

import numpy as np
import pytest
import rtde_control  # noqa: E402,F401 - the test extra installs ur_rtde; a missing one must fail, not skip
from loopback_helpers import (
    FAST,
    PLACEMENT,
    STIFFNESS,
    SURFACE_Z,
    FakeSkin,
    at_rest,
    free_loopback_host,
    in_contact,
)  # noqa: E402
from timing import FeedStall, LatenessProbe, MachineProbe, unless_the_feed_stalled

from aptkt.robot import UR10, Robot, SafetyLimits  # noqa: E402
from aptkt.sim.loopback import Loopback  # noqa: E402


def test_connects_uploads_the_control_script_and_arms_the_controller_watchdog(robot, loopback):
    assert isinstance(robot, Robot)
    assert robot.frequency == 125.0  # CB3 controller version
    state = loopback.state()
    assert state["program"] == "rtde_control" and state["program_running"]
    assert state["watchdog"] == {
        "variable": "input_int_register_0",
        "min_frequency": 2.0,
        "action": "stop",
    }
    assert "def rtde_control():" in loopback.scripts()[-1]


def test_move_above_reaches_the_point_above_the_object(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _move_above_reaches_the_point_above_the_object(robot, loopback)
    )


def _move_above_reaches_the_point_above_the_object(robot, loopback):
    robot.move_above(PLACEMENT, 0.01)
    state = at_rest(loopback)
    np.testing.assert_allclose(
        state["pose"][:3], [PLACEMENT.x, PLACEMENT.y, SURFACE_Z + 0.01], atol=1e-6
    )
    assert not state["moving"]


def test_move_above_leaves_an_object_vertically_first(make_robot, on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _move_above_leaves_an_object_vertically_first(robot, loopback),
        robot=lambda: make_robot(pose=(0.02, -0.5, 0.002, np.pi, 0.0, 0.0)),  # low, beside it
    )


def _move_above_leaves_an_object_vertically_first(robot, loopback):
    start = time.monotonic_ns()
    robot.move_above(PLACEMENT, 0.01)
    poses = robot.trace(start)["tcp_pose"]
    rising = poses[:, 2] < SURFACE_Z + 0.01 - 1e-4
    # While still below the travel height the arm only goes up: x stays where it was.
    np.testing.assert_allclose(poses[rising, 0], 0.02, atol=1e-9)
    np.testing.assert_allclose(loopback.state()["pose"][:3], [0.0, -0.5, 0.01], atol=1e-6)


def test_approach_stops_at_light_contact(on_a_healthy_arm, loopback):
    on_a_healthy_arm(lambda robot, skin: _approach_stops_at_light_contact(robot, loopback, skin))


def _approach_stops_at_light_contact(robot, loopback, skin):
    robot.move_above(PLACEMENT, 0.004)
    loopback.clock_lag()  # from here on
    with _Lateness() as late:
        start = time.monotonic_ns()
        z = robot.approach_contact(skin, 0.05)
    lag = loopback.clock_lag()
    state = at_rest(loopback)
    speed = FAST["approach_speed"]
    # The contact was detected on the first skin reading above 0.05 N: 0.25 mm into a 200 N/m
    # surface, give or take the travel between two readings.
    felt = [(t, f) for t, f in skin.readings if f > 0.05]
    assert felt, "no skin reading above the threshold"
    felt_at, force = felt[0]
    before = [t for t, f in skin.readings if t < felt_at]
    assert 0.05 < force <= 0.05 + STIFFNESS * speed * (felt_at - before[-1]) + 1e-9
    z_felt = SURFACE_Z - force / STIFFNESS
    # The contact point is the pose of the sample that read the skin. The RTDE pose is older
    # than the skin's reading by however long it took to arrive (longer on a busy machine),
    # and on that clock the arm was higher by exactly the distance it travelled since.
    trace = robot.trace(start)
    sample = np.flatnonzero(trace["tcp_pose"][:, 2] == z)
    assert sample.size, "the contact point is not a sampled pose"
    posed_at = trace["robot_timestamp"][sample[-1]]
    assert posed_at <= felt_at
    assert z == pytest.approx(z_felt + speed * (felt_at - posed_at), abs=1e-6)
    assert not state["moving"] and state["motion"] is None
    # It stopped right there: below the point it felt, past it by the stopping ramp
    # (v^2/2a = 0.1 mm) plus the travel until the stop was sent: two control periods, and
    # however late this process or the controller ran.
    margin = 0.1e-3 + speed * (2 / robot.frequency + late.seconds + lag)
    assert z_felt - margin < state["pose"][2] <= z_felt
    assert 0.05 < state["normal_force"]


class _Lateness:
    """How late this process ran work that asks for a fifth of a core on time, while a test's
    motion ran (tests/helpers/timing.py): the margin a duration measured on the host needs
    beyond the test's own, since a sample read late is stamped late."""

    def __enter__(self) -> _Lateness:
        self._probe = LatenessProbe(period=0.005, work=0.001, catch_up=2.0).start()
        self._since = time.monotonic()
        return self

    def __exit__(self, *exc: object) -> None:
        self.seconds = self._probe.worst(self._since)
        self._probe.stop()


def test_press_indents_to_the_depth_and_holds_still(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _press_indents_to_the_depth_and_holds_still(robot, loopback, skin)
    )


def _press_indents_to_the_depth_and_holds_still(robot, loopback, skin):
    z = in_contact(robot, skin)
    with _Lateness() as late:
        start = time.monotonic_ns()
        robot.press(0.002, 0.4)
        end = time.monotonic_ns()
    state = at_rest(loopback)
    assert state["pose"][2] == pytest.approx(z - 0.002, abs=1e-6)
    assert state["normal_force"] == pytest.approx(STIFFNESS * (SURFACE_Z - (z - 0.002)), rel=1e-6)
    trace = robot.trace(start, end)
    still = np.abs(trace["tcp_pose"][:, 2] - (z - 0.002)) < 1e-9
    held = (trace["host_t_ns"][still][-1] - trace["host_t_ns"][still][0]) * 1e-9
    margin = 0.02 + late.seconds
    assert held >= 0.4 - margin
    start_ns, stop_ns = robot.action_window_ns
    assert (stop_ns - start_ns) * 1e-9 == pytest.approx(0.4, abs=margin)
    in_window = (trace["host_t_ns"] >= start_ns) & (trace["host_t_ns"] < stop_ns)
    assert np.all(still[in_window])  # the window is the hold
    # From the control cycle after landing on, the arm does not move at all (read at 125 Hz:
    # a stall of the reader costs one sample per control period it lasts).
    landed = trace["robot_timestamp"][still][0]
    after = trace["robot_timestamp"] > landed + 1e-6
    assert after.sum() >= max(1, 30 - int(late.seconds * 125))
    assert np.all(np.linalg.norm(trace["tcp_speed"][after, :3], axis=1) == 0.0)


def test_slide_keeps_the_normal_force_at_constant_tangential_speed(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _slide_keeps_the_normal_force_at_constant_tangential_speed(
            robot, loopback, skin
        )
    )


def _slide_keeps_the_normal_force_at_constant_tangential_speed(robot, loopback, skin):
    in_contact(robot, skin)
    x0 = loopback.state()["pose"][0]
    loopback.clock_lag()  # from here on
    with _Lateness() as late:
        start = time.monotonic_ns()
        robot.slide(0.2, 0.02, 0.6, (1.0, 0.0), skin)
    lag = loopback.clock_lag()
    trace = robot.trace(start)
    state = at_rest(loopback)
    vx = trace["tcp_speed"][:, 0]
    cruising = vx > 0.02 - 1e-9
    # At full speed for the whole slide duration, and that is the reported action window.
    start_ns, stop_ns = robot.action_window_ns
    assert (stop_ns - start_ns) * 1e-9 == pytest.approx(0.6)
    window = (trace["host_t_ns"] >= start_ns + 20_000_000) & (trace["host_t_ns"] < stop_ns)
    assert np.all(cruising[window])
    # Seen throughout the window: a busy host reads fewer samples (44 of the controller's 72
    # were seen once), but no stretch of the controller's clock went unseen for longer than
    # the reading was kept waiting, give or take 20 ms and however late the controller ran (a
    # late controller sends its packets in bursts). Two threads of this process read: the
    # supervision loop, as late as a probe thread of the process (`late`), and ur_rtde's
    # receiving thread, whose wait shows in the trace itself as the age of the data read (a
    # loaded run missed 32 ms of samples with the probe 6.5 ms late: the receiving thread
    # had been kept waiting, which the probe does not see).
    seen = trace["robot_timestamp"][window]
    read = trace["host_t_ns"][window] * 1e-9
    age = (read - seen) - (read - seen).min()  # past the freshest read's
    waited = np.maximum(late.seconds, age[:-1])
    assert seen.size >= 2 and np.all(np.diff(seen) <= 0.02 + lag + waited), (
        np.diff(seen).max(),
        late.seconds,
        age.max(),
        lag,
    )
    margin = 0.02 + late.seconds + lag
    assert seen[-1] - seen[0] >= 0.58 - 2 * margin
    np.testing.assert_allclose(
        trace["tcp_speed"][cruising, 1], 0.0, atol=1e-12
    )  # no sideways drift
    np.testing.assert_allclose(trace["skin_force"][cruising], 0.2, rtol=0.15)  # the settle band
    # Force control keeps working during the slide: the end is closer to 0.2 N than the start.
    assert abs(trace["skin_force"][cruising][-1] - 0.2) < 0.005
    travelled = state["pose"][0] - x0
    # 0.6 s at full speed plus the two ramps (v^2/a = 0.8 mm), and on for as long as this
    # process or the controller ran late to stop it (2.1 mm more was seen at a load of 7).
    planned = 0.02 * 0.6 + 0.02**2 / 0.5
    assert planned - 0.0005 <= travelled <= planned + 0.0005 + 0.02 * (late.seconds + lag), (
        travelled,
        late.seconds,
        lag,
    )
    assert not state["force_mode"] and not state["moving"]


def test_slide_follows_the_given_direction(on_a_healthy_arm, loopback):
    on_a_healthy_arm(lambda robot, skin: _slide_follows_the_given_direction(robot, loopback, skin))


def _slide_follows_the_given_direction(robot, loopback, skin):
    in_contact(robot, skin)
    p0 = np.array(loopback.state()["pose"][:2])
    robot.slide(0.1, 0.01, 0.5, (0.0, -2.0), skin)
    moved = np.array(at_rest(loopback)["pose"][:2]) - p0
    assert moved[1] < -0.004 and abs(moved[0]) < 1e-6


def test_lift_then_wait_out_of_contact(on_a_healthy_arm, loopback):
    on_a_healthy_arm(lambda robot, skin: _lift_then_wait_out_of_contact(robot, loopback, skin))


def _lift_then_wait_out_of_contact(robot, loopback, skin):
    z = in_contact(robot, skin)
    robot.press(0.001, 0.0)
    robot.lift(0.01)
    state = at_rest(loopback)
    assert state["pose"][2] == pytest.approx(z - 0.001 + 0.01, abs=1e-6)
    assert state["normal_force"] == 0.0
    t0 = time.monotonic()
    robot.wait(0.3)
    assert time.monotonic() - t0 >= 0.3
    assert loopback.state()["pose"][2] == pytest.approx(z - 0.001 + 0.01, abs=1e-9)


def test_lift_is_capped_at_the_top_of_the_workspace_box(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _lift_is_capped_at_the_top_of_the_workspace_box(robot, loopback, skin)
    )


def _lift_is_capped_at_the_top_of_the_workspace_box(robot, loopback, skin):
    in_contact(robot, skin)
    robot.lift(1.0)
    assert at_rest(loopback)["pose"][2] == pytest.approx(PLACEMENT.workspace_max[2], abs=1e-5)


def test_a_whole_exploratory_action_keeps_the_controller_running(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _a_whole_exploratory_action_keeps_the_controller_running(
            robot, loopback, skin
        )
    )


def _a_whole_exploratory_action_keeps_the_controller_running(robot, loopback, skin):
    for _ in range(2):
        in_contact(robot, skin)
        robot.press(0.001, 0.1)
        robot.lift(0.005)
        robot.wait(0.05)
    state = loopback.state()
    assert state["program_running"] and not state["protective_stopped"]


def test_recording_metadata_relates_host_and_robot_clocks(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _recording_metadata_relates_host_and_robot_clocks(robot, loopback, skin)
    )


def _recording_metadata_relates_host_and_robot_clocks(robot, loopback, skin):
    in_contact(robot, skin)
    loopback.clock_lag()  # from here on
    with _Lateness() as late:
        start = robot.now_ns()
        robot.press(0.001, 0.3)
        stop = robot.now_ns()
    lag = loopback.clock_lag()
    meta = robot.recording_metadata(start, stop)
    trace = meta["robot_trace"]
    host = np.array(trace["host_t_ns"])
    robot_t = np.array(trace["robot_timestamp"])
    assert len(host) > 20 * (1 - late.seconds / 0.3) and np.all((host >= start) & (host < stop))
    assert np.all(np.diff(robot_t) >= 0) and robot_t[-1] > robot_t[0]
    # host - robot clock is one offset, up to the read latency of a few control periods,
    # however late this process read, and however far the simulated controller's own clock
    # fell behind (a real controller's keeps time; the loopback's runs late when its process
    # is kept waiting, and catches up).
    spread = (host - robot_t * 1e9) - meta["robot_clock_offset_ns"]
    assert np.max(np.abs(spread)) < 30e6 + (late.seconds + lag) * 1e9
    assert meta["robot_frequency_hz"] == 125.0
    assert np.array(trace["skin_force"]).max() > 0.1


def test_the_clock_is_the_one_given(loopback):
    ticks = iter(range(10**6))
    robot = UR10(loopback.host, connect=False, clock=lambda: next(ticks))
    assert robot.now_ns() == 0 and robot.now_ns() == 1


def test_e_series_controller_runs_at_500_hz():
    with Loopback(
        free_loopback_host(),
        series="e-series",
        contact={"type": "spring", "surface_z": SURFACE_Z, "stiffness": STIFFNESS},
        start_pose=(0.0, -0.5, 0.006, np.pi, 0.0, 0.0),
    ) as lb:
        machine = MachineProbe()
        try:
            unless_the_feed_stalled(
                FeedStall(lb, machine),
                lambda: _an_e_series_runs_at_500_hz(lb),
                SafetyLimits().watchdog_timeout,
            )
        finally:
            machine.close()


def _an_e_series_runs_at_500_hz(lb: Loopback) -> None:
    lb.reset(pose=(0.0, -0.5, 0.006, np.pi, 0.0, 0.0))
    robot = UR10(lb.host, [PLACEMENT], SafetyLimits(approach_speed=0.01))
    try:
        assert robot.frequency == 500.0
        z = in_contact(robot, FakeSkin(lb))
        robot.press(0.001, 0.1)
        assert lb.state()["pose"][2] == pytest.approx(z - 0.001, abs=1e-6)
        robot.lift(0.005)
    finally:
        robot.close()
