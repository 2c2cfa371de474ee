"""Every fault path of the UR10 backend leaves the arm stopped and raises a typed error.

Faults are injected into the loopback controller (protective stop, program stop, dropped or
frozen network, trajectory faults) or into the fake skin, in the middle of a movement.

After a fault the backend stops the arm and retracts it while feeding the controller's
watchdog (0.5 s) from its supervision loop alone. A loaded machine can keep that feed waiting
for longer (it crosses three processes); the controller then stops the program mid-retract, as
designed, and the retract cannot be checked. Such a run is measured and repeated
(:func:`stops_and_retracts`); a failure without such a stall fails at once.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest
import rtde_control  # noqa: E402,F401 - the test extra installs ur_rtde; a missing one must fail, not skip
from loopback_helpers import (  # noqa: E402
    PLACEMENT,
    SURFACE_Z,
    FakeSkin,
    at_rest,
    fire_after,
    in_contact,
)

from aptkt.errors import (  # noqa: E402
    ProgramStoppedError,
    ProtectiveStopError,
    RobotConnectionError,
    RobotError,
    SafetyLimitError,
    SkinDisconnectedError,
)
from aptkt.robot import UR10, Placement  # noqa: E402
from aptkt.sim.loopback import Loopback  # noqa: E402


def assert_stopped_and_retracted(
    loopback, z_before: float, raised: pytest.ExceptionInfo | None = None
) -> dict:
    """The arm is at rest, under program control, and above where the fault caught it."""
    state = at_rest(loopback, 0.1)
    why = f"{state}\nnotes: {getattr(raised.value, '__notes__', None) if raised else None}"
    assert not state["moving"], why
    assert state["motion"] is None and not state["force_mode"], why
    assert state["program_running"] and not state["protective_stopped"], why
    assert state["pose"][2] > z_before + 0.005, why  # retracted upwards
    assert state["normal_force"] == 0.0, why
    return state


def stops_and_retracts(
    loopback: Loopback,
    on_a_healthy_arm: Callable[..., None],
    fault: Callable[[UR10, FakeSkin], tuple[float, pytest.ExceptionInfo | None]],
    robot: Callable[[], UR10] | None = None,
) -> dict:
    """``fault(robot, skin)`` raises the expected error mid-movement and returns how high the
    arm was when caught (and the error); the arm must then be stopped and retracted
    (:func:`assert_stopped_and_retracted`). Each attempt gets a healthy robot (or ``robot()``)
    and a new skin, and one that the machine disturbed is repeated (``on_a_healthy_arm``)."""
    state: dict = {}

    def check(arm: UR10, skin: FakeSkin) -> None:
        z_before, raised = fault(arm, skin)
        state.update(assert_stopped_and_retracted(loopback, z_before, raised))

    on_a_healthy_arm(check, **({"robot": robot} if robot else {}))
    return state


# ----------------------------------------------------------------------------- force limits
def test_skin_force_above_the_limit_mid_press(on_a_healthy_arm, loopback):
    def fault(robot: UR10, skin: FakeSkin):
        z = in_contact(robot, skin)
        skin.scale = 40.0  # the skin now reads 40x the contact force: 0.2 N looks like 8 N
        with pytest.raises(
            SafetyLimitError, match="skin normal force .* exceeds max_normal_force 5.0"
        ) as raised:
            robot.press(0.002, 1.0)
        return z - 0.002, raised

    stops_and_retracts(loopback, on_a_healthy_arm, fault)


def test_tcp_wrench_above_the_limit_when_the_skin_feels_nothing(
    make_robot, on_a_healthy_arm, loopback
):
    # A dead skin (fresh readings of 0 N) lets the approach run into a stiff object; the TCP
    # wrench catches it at 5 N = 1 mm into a 5000 N/m surface.
    def fault(robot: UR10, skin: FakeSkin):
        skin.dead = True
        robot.move_above(PLACEMENT, 0.004)
        with pytest.raises(
            SafetyLimitError, match="TCP wrench along the normal .* exceeds max_normal_force"
        ) as raised:
            robot.approach_contact(skin, 0.05)
        return -0.001, raised

    stiff = {"type": "spring", "surface_z": 0.0, "stiffness": 5000.0}
    state = stops_and_retracts(loopback, on_a_healthy_arm, fault, lambda: make_robot(contact=stiff))
    assert state["pose"][2] < 0.04  # a retract, not a flight


def test_no_contact_within_the_approach_travel(make_robot, on_a_healthy_arm, loopback):
    def fault(robot: UR10, skin: FakeSkin):
        robot.move_above(PLACEMENT, 0.004)
        with pytest.raises(SafetyLimitError, match="no contact .* approach travel limit") as raised:
            robot.approach_contact(skin, 0.05)
        return 0.004 - 0.006, raised

    lower = {"type": "spring", "surface_z": -0.02}  # the object is lower than configured
    new_robot = lambda: make_robot(contact=lower, max_approach_travel=0.006)  # noqa: E731
    stops_and_retracts(loopback, on_a_healthy_arm, fault, new_robot)


def test_nan_from_the_skin_is_a_fault(on_a_healthy_arm, loopback):
    def fault(robot: UR10, skin: FakeSkin):
        z = in_contact(robot, skin)
        skin.nan_after = 0.1
        skin.arm()
        with pytest.raises(SafetyLimitError, match="non-finite") as raised:
            robot.press(0.001, 1.0)
        return z - 0.001, raised

    stops_and_retracts(loopback, on_a_healthy_arm, fault)


# ----------------------------------------------------------------------------- speed / acceleration
def test_measured_speed_above_the_limit(make_robot, on_a_healthy_arm, loopback):
    def fault(robot: UR10, skin: FakeSkin):
        in_contact(robot, skin)
        robot.lift(0.004)
        z = loopback.state()["pose"][2]
        # A trajectory fault: the controller accelerates the arm sideways within the
        # acceleration limit until the speed limit (x1.5 tolerance = 0.03 m/s) trips.
        fire_after(0.1, lambda: loopback.disturb([0.0, 0.1, 0.0], duration=2.0, acceleration=0.3))
        with pytest.raises(
            SafetyLimitError, match="measured TCP speed .* exceeds the limit 0.02"
        ) as raised:
            robot.wait(2.0)
        return z - 0.006, raised

    stops_and_retracts(loopback, on_a_healthy_arm, fault, lambda: make_robot(max_speed=0.02))


def test_measured_acceleration_above_the_limit(on_a_healthy_arm, loopback):
    def fault(robot: UR10, skin: FakeSkin):
        in_contact(robot, skin)
        robot.lift(0.004)
        z = loopback.state()["pose"][2]
        # A velocity step of 5 cm/s within one control period (about 1.7 m/s^2 over the 30 ms
        # the backend averages over), at a speed well below the speed limit.
        fire_after(0.1, lambda: loopback.disturb([0.05, 0.0, 0.0], duration=2.0))
        with pytest.raises(
            SafetyLimitError, match="measured TCP acceleration .* exceeds the limit 0.5"
        ) as raised:
            robot.wait(2.0)
        return z - 0.006, raised

    stops_and_retracts(loopback, on_a_healthy_arm, fault)


def test_commands_beyond_the_limits_are_refused_before_moving(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _commands_beyond_the_limits_are_refused_before_moving(
            robot, loopback, skin
        )
    )


def _commands_beyond_the_limits_are_refused_before_moving(robot, loopback, skin):
    in_contact(robot, skin)
    before = at_rest(loopback)["pose"]
    with pytest.raises(SafetyLimitError, match="slide speed 0.2 m/s exceeds max_speed 0.1"):
        robot.slide(0.1, 0.2, 0.1, (1.0, 0.0), skin)
    with pytest.raises(SafetyLimitError, match="slide force 6.0 N exceeds max_normal_force"):
        robot.slide(6.0, 0.01, 0.1, (1.0, 0.0), skin)
    with pytest.raises(SafetyLimitError, match="press depth 6.00 mm exceeds max_depth 5.00 mm"):
        robot.press(0.006, 0.1)
    with pytest.raises(SafetyLimitError, match="contact threshold 5.0 N is not below"):
        robot.approach_contact(skin, 5.0)
    state = loopback.state()
    assert state["pose"] == before and not state["moving"] and not state["force_mode"]


# ----------------------------------------------------------------------------- workspace
def test_a_slide_that_would_leave_the_box_is_refused(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _a_slide_that_would_leave_the_box_is_refused(robot, loopback, skin)
    )


def _a_slide_that_would_leave_the_box_is_refused(robot, loopback, skin):
    in_contact(robot, skin)
    before = at_rest(loopback)["pose"]
    with pytest.raises(SafetyLimitError, match="slide would leave the workspace box of 'sponge'"):
        robot.slide(0.1, 0.05, 1.0, (1.0, 0.0), skin)  # 5 cm from the centre of an 8 cm box
    assert loopback.state()["pose"] == before


def test_a_target_outside_the_box_is_refused(robot, loopback):
    with pytest.raises(SafetyLimitError, match="outside its workspace box"):
        robot.move_above(PLACEMENT, 0.05)  # the box ends 4 cm above the surface
    assert not loopback.state()["moving"]


def test_leaving_the_box_mid_action(on_a_healthy_arm, loopback):
    narrow = Placement("coin", 0.0, -0.5, 0.0, (-0.003, -0.503, -0.01), (0.003, -0.497, 0.02))

    def fault(robot: UR10, skin: FakeSkin):
        robot.move_above(narrow, 0.004)
        z = robot.approach_contact(skin, 0.05)
        # Drift sideways within the speed and acceleration limits until the 3 mm margin is
        # gone.
        fire_after(0.1, lambda: loopback.disturb([0.01, 0.0, 0.0], duration=3.0, acceleration=0.2))
        with pytest.raises(SafetyLimitError, match="left the workspace box of 'coin'") as raised:
            robot.press(0.001, 3.0)
        return z - 0.001, raised

    state = stops_and_retracts(loopback, on_a_healthy_arm, fault)
    assert 0.003 < state["pose"][0] < 0.0045


# ----------------------------------------------------------------------------- controller faults
def test_protective_stop_mid_slide(on_a_healthy_arm, loopback):
    on_a_healthy_arm(lambda robot, skin: _protective_stop_mid_slide(robot, loopback, skin))


def _protective_stop_mid_slide(robot, loopback, skin):
    in_contact(robot, skin)
    fire_after(0.8, loopback.protective_stop)
    with pytest.raises(ProtectiveStopError):
        robot.slide(0.2, 0.01, 2.0, (1.0, 0.0), skin)
    state = at_rest(loopback)
    assert state["protective_stopped"] and not state["moving"] and not state["program_running"]
    # Nothing more moves until the operator recovers the arm.
    with pytest.raises(ProtectiveStopError):
        robot.lift(0.01)
    assert not at_rest(loopback)["moving"]


def test_recover_after_a_protective_stop(on_a_healthy_arm, loopback):
    on_a_healthy_arm(lambda robot, skin: _recover_after_a_protective_stop(robot, loopback, skin))


def _recover_after_a_protective_stop(robot, loopback, skin):
    in_contact(robot, skin)
    loopback.protective_stop()
    with pytest.raises(ProtectiveStopError):
        robot.press(0.001, 0.5)
    robot.recover()  # unlock through the dashboard, re-upload the control script
    state = loopback.state()
    assert state["program_running"] and not state["protective_stopped"]
    robot.move_above(PLACEMENT, 0.01)
    assert at_rest(loopback)["pose"][2] == pytest.approx(0.01, abs=1e-6)


def test_program_stopped_mid_press(on_a_healthy_arm, loopback):
    on_a_healthy_arm(lambda robot, skin: _program_stopped_mid_press(robot, loopback, skin))


def _program_stopped_mid_press(robot, loopback, skin):
    in_contact(robot, skin)
    fire_after(0.3, lambda: loopback.stop_program("operator pressed stop"))
    with pytest.raises(ProgramStoppedError):
        robot.press(0.001, 2.0)
    state = at_rest(loopback)
    assert not state["program_running"] and not state["moving"]


# ----------------------------------------------------------------------------- the watchdog
def _hold_the_gil(seconds: float) -> float:
    """One C call that never returns to the interpreter's loop for at least ``seconds`` (as an
    HDF5 write or a module being loaded can): no other thread of this process runs meanwhile.
    Returns how long it held; a call that fell short (a machine that sped up after the
    calibration) is repeated longer."""
    n = 1_000_000
    start = time.perf_counter()
    sum(range(n))
    n = int(n * seconds / max(time.perf_counter() - start, 1e-6))
    while True:
        start = time.perf_counter()
        sum(range(n))
        held = time.perf_counter() - start
        if held >= seconds:
            return held
        n *= 2


def test_an_idle_arm_outlasts_its_process_holding_the_gil(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _an_idle_arm_outlasts_its_process_holding_the_gil(robot, loopback)
    )


def _an_idle_arm_outlasts_its_process_holding_the_gil(robot, loopback):
    """While the arm is idle the control process feeds the controller's watchdog: this
    process holding its GIL for twice the watchdog's period (say, writing a large recording)
    must not let the controller stop the program of an arm at rest."""
    period = robot.limits.watchdog_timeout
    assert loopback.state()["program_running"]
    assert _hold_the_gil(2.0 * period) >= 2.0 * period
    time.sleep(period)  # (a stop would have come by now)
    state = loopback.state()
    assert state["program_running"], state["text_log"][-5:]
    robot.move_above(PLACEMENT, 0.01)
    assert at_rest(loopback)["program_running"]


def test_a_stalled_supervision_loop_lets_the_controller_stop_the_arm(on_a_healthy_arm, loopback):
    on_a_healthy_arm(
        lambda robot, skin: _a_stalled_supervision_loop_lets_the_controller_stop_the_arm(
            robot, loopback, skin
        )
    )


def _a_stalled_supervision_loop_lets_the_controller_stop_the_arm(robot, loopback, skin):
    """During a movement only the supervision loop feeds the watchdog (the control process's
    keep-alive is off): a loop stalled for twice the watchdog's period — here a skin reading
    that blocks — lets the controller stop the program, and with it the arm."""
    period = robot.limits.watchdog_timeout
    robot.move_above(PLACEMENT, 0.004)
    calls = 0

    def blocking_skin() -> float:
        nonlocal calls
        calls += 1
        if calls == 3:
            time.sleep(2.0 * period)
        return skin()

    with pytest.raises(RobotError):
        robot.approach_contact(blocking_skin, 0.05)
    state = at_rest(loopback)
    assert not state["program_running"] and not state["moving"], state
    assert state["text_log"][-1].startswith("program stopped: RTDE input watchdog"), state


# ----------------------------------------------------------------------------- lost link
def test_dropped_connection_mid_slide(make_robot, loopback, skin):
    robot = make_robot()
    in_contact(robot, skin)
    fire_after(0.8, lambda: loopback.drop_connections(refuse_for=None))
    t0 = time.monotonic()
    with pytest.raises(RobotConnectionError, match="lost the link"):
        robot.slide(0.2, 0.01, 3.0, (1.0, 0.0), skin)
    assert time.monotonic() - t0 < 2.0  # noticed at once, not after ur_rtde's timeouts
    # The controller's RTDE watchdog (2 Hz) stops the program that was still sliding.
    time.sleep(0.6)
    state = loopback.state()
    assert not state["program_running"] and not state["moving"]
    assert "RTDE input watchdog" in state["stop_reason"]
    # Later commands fail fast instead of blocking on ur_rtde's stale state.
    t0 = time.monotonic()
    with pytest.raises(RobotConnectionError, match="call recover"):
        robot.lift(0.01)
    assert time.monotonic() - t0 < 0.1


def test_a_drop_during_the_approach_ends_at_the_controllers_watchdog(make_robot, loopback, skin):
    """What docs/reliability.md states: with the link gone nothing can stop the guarded
    approach but the controller's RTDE watchdog, so the arm goes on down at approach_speed for
    up to watchdog_timeout (into the object if it gets there), then stops; nothing retracts it."""
    speed, timeout, accel = 0.005, 0.5, 0.5  # the default limits
    robot = make_robot(approach_speed=speed, max_approach_travel=0.05)
    robot.move_above(PLACEMENT, 0.004)
    at_drop: dict = {}

    def drop() -> None:
        at_drop.update(loopback.state())
        loopback.drop_connections(refuse_for=None)

    fire_after(0.5, drop)  # 2.5 mm down: 1.5 mm above the surface
    with pytest.raises(RobotConnectionError):
        robot.approach_contact(skin, 0.05)
    time.sleep(timeout + 0.5)
    state = at_rest(loopback, 0.1)
    assert not state["program_running"] and "RTDE input watchdog" in state["stop_reason"]
    travel = at_drop["pose"][2] - state["pose"][2]
    # At most approach_speed x watchdog_timeout (+ the stop's v^2 / 2a, and one control cycle
    # of slack per end) further: 2.5 mm here, ending 1 mm into the object.
    assert travel <= speed * timeout + speed**2 / (2 * accel) + 0.0004, travel
    assert travel > 0.5 * speed * timeout, travel  # it did go on: nothing else stopped it
    assert state["pose"][2] < SURFACE_Z and state["normal_force"] > 0.0  # still pressing
    loopback.restore()


def test_frozen_network_mid_press(make_robot, loopback, skin):
    robot = make_robot()
    z = in_contact(robot, skin)
    fire_after(0.5, loopback.freeze)
    t0 = time.monotonic()
    with pytest.raises(RobotConnectionError, match="no fresh robot data"):
        robot.press(0.001, 3.0)
    assert time.monotonic() - t0 < 0.5 + 0.5 + 0.3  # the 0.5 s watchdog, plus slack
    time.sleep(0.6)
    state = loopback.state()
    assert not state["program_running"] and not state["moving"]
    assert state["pose"][2] == pytest.approx(z - 0.001, abs=1e-6)
    loopback.freeze(False)


def test_lost_link_is_reported_when_connecting_fails(loopback, make_robot):
    from aptkt.robot import UR10

    make_robot()  # closes the shared client; then nobody listens on a free loopback address
    with pytest.raises(
        RobotConnectionError, match="cannot connect to the UR controller at 127.0.0.250"
    ):
        UR10("127.0.0.250")


# ----------------------------------------------------------------------------- stale or broken skin
def test_stale_skin_mid_press(on_a_healthy_arm, loopback):
    def fault(robot: UR10, skin: FakeSkin):
        z = in_contact(robot, skin)
        skin.stale_after = 0.2
        skin.arm()
        t0 = time.monotonic()
        with pytest.raises(SkinDisconnectedError, match="no fresh skin data") as raised:
            robot.press(0.001, 3.0)
        # Stale after 0.2 s, noticed 0.5 s later (the watchdog), then a 1 cm retract (~0.35 s).
        assert time.monotonic() - t0 < 0.2 + 0.5 + 0.35 + 0.3
        return z - 0.001, raised

    stops_and_retracts(loopback, on_a_healthy_arm, fault)


def test_skin_failure_mid_slide_is_reraised_after_retracting(on_a_healthy_arm, loopback):
    def fault(robot: UR10, skin: FakeSkin):
        z = in_contact(robot, skin)
        skin.raise_after = (0.7, SkinDisconnectedError("/dev/ttyUSB0 unplugged"))
        skin.arm()
        with pytest.raises(SkinDisconnectedError, match="unplugged") as raised:
            robot.slide(0.2, 0.01, 2.0, (1.0, 0.0), skin)
        return z - 0.002, raised

    stops_and_retracts(loopback, on_a_healthy_arm, fault)


def test_force_that_cannot_be_established_is_an_error(make_robot, loopback, skin):
    robot = make_robot()
    robot.establish_timeout = 0.4
    in_contact(robot, skin)
    skin.scale = 0.1  # the skin under-reads: 0.2 N is never seen within the timeout
    with pytest.raises(RobotError, match="establishing 0.2 N did not finish"):
        robot.slide(0.2, 0.01, 1.0, (1.0, 0.0), skin)
    state = at_rest(loopback, 0.1)
    assert not state["moving"] and not state["force_mode"] and state["program_running"]


def test_misuse_is_a_clear_error(on_a_healthy_arm):
    on_a_healthy_arm(lambda robot, skin: _misuse_is_a_clear_error(robot, skin))


def _misuse_is_a_clear_error(robot, skin):
    with pytest.raises(RobotError, match="needs move_above"):
        robot.approach_contact(skin, 0.05)
    robot.move_above(PLACEMENT, 0.004)
    with pytest.raises(RobotError, match="needs approach_contact"):
        robot.press(0.001, 0.1)
    with pytest.raises(ValueError, match="clearance must be a finite number > 0"):
        robot.move_above(PLACEMENT, float("nan"))
    with pytest.raises(ValueError, match="slide direction must not be zero"):
        in_contact(robot, skin)
        robot.slide(0.1, 0.01, 0.1, (0.0, 0.0), skin)
    assert np.isfinite(robot.now_ns())


def test_close_destroys_the_clients_even_while_a_fault_is_kept(make_robot, skin):
    # ur_rtde's destructor sleeps 0.5 s holding the GIL; if a kept traceback delayed it to
    # some later garbage collection, it would stall another connection's supervision loop.
    import weakref

    robot = make_robot()
    in_contact(robot, skin)
    skin.nan_after = 0.0
    skin.arm()
    with pytest.raises(SafetyLimitError) as kept:
        robot.press(0.001, 1.0)
    clients = [weakref.ref(robot._control), weakref.ref(robot._receive)]
    robot.close()
    assert kept.value.__traceback__ is not None
    assert [c() for c in clients] == [None, None]


def test_recover_after_a_stopped_program(on_a_healthy_arm, loopback):
    on_a_healthy_arm(lambda robot, skin: _recover_after_a_stopped_program(robot, loopback, skin))


def _recover_after_a_stopped_program(robot, loopback, skin):
    in_contact(robot, skin)
    loopback.stop_program("operator pressed stop")
    time.sleep(0.05)  # see test_a_command_racing_a_program_stop_fails_fast for the race
    with pytest.raises(ProgramStoppedError):
        robot.press(0.001, 0.5)
    robot.recover()
    assert loopback.state()["program_running"]
    robot.move_above(PLACEMENT, 0.01)
    assert at_rest(loopback)["pose"][2] == pytest.approx(0.01, abs=1e-6)


def test_recover_after_a_lost_link(make_robot, loopback, skin):
    robot = make_robot()
    in_contact(robot, skin)
    loopback.drop_connections(refuse_for=None)
    # A command racing the drop: ur_rtde would wait for its stale state (up to 300 s).
    t0 = time.monotonic()
    with pytest.raises(RobotConnectionError):
        robot.press(0.001, 1.0)
    assert time.monotonic() - t0 < robot.limits.watchdog_timeout + 0.3
    with pytest.raises(RobotConnectionError, match="cannot connect"):
        robot.recover()  # the controller is still unreachable
    loopback.restore()
    robot.recover()
    state = loopback.state()
    assert state["program_running"] and state["connections"].get("rtde") == 2
    robot.move_above(PLACEMENT, 0.01)
    assert at_rest(loopback)["pose"][2] == pytest.approx(0.01, abs=1e-6)


@pytest.mark.slow
def test_a_command_racing_a_program_stop_fails_fast(make_robot, loopback, skin):
    robot = make_robot()
    in_contact(robot, skin)
    # Stopped before the script answered "ready" to the approach's last command: ur_rtde's
    # next command then spins up to 4 s for that "ready" (as with a real controller).
    loopback.stop_program("operator pressed stop")
    t0 = time.monotonic()
    with pytest.raises(ProgramStoppedError):
        robot.press(0.001, 0.5)
    assert time.monotonic() - t0 < 0.5
    assert not at_rest(loopback)["moving"]
    robot.close()  # lets the spinning call end, so the connection really closes
    deadline = time.monotonic() + 2.0
    while loopback.state()["connections"].get("rtde") and time.monotonic() < deadline:
        time.sleep(0.02)
    assert not loopback.state()["connections"].get("rtde")


def test_a_crash_of_the_control_client_is_a_lost_link_not_a_crash(make_robot, loopback, skin):
    """ur_rtde's control client may crash when its link drops (its reconnect races our calls):
    it runs in a process of its own, so that is a lost link; the arm stops and nothing hangs."""
    import os
    import signal

    robot = make_robot()
    in_contact(robot, skin)
    pid = robot._control.pid
    fire_after(0.3, lambda: os.kill(pid, signal.SIGSEGV))
    t0 = time.monotonic()
    with pytest.raises(RobotConnectionError, match="control client process ended"):
        robot.press(0.001, 3.0)
    assert time.monotonic() - t0 < 1.5
    time.sleep(0.7)  # the controller's RTDE watchdog stops the program
    assert not loopback.state()["moving"]
    robot.recover()  # a new control process
    robot.move_above(PLACEMENT, 0.01)
    assert at_rest(loopback)["pose"][2] == pytest.approx(0.01, abs=1e-6)


def test_nothing_of_a_dropped_link_reconnects_behind_our_back(make_robot, loopback, skin):
    """After a drop the controller accepts connections again at once: ur_rtde's control client
    would reconnect by itself and keep the controller's command registers from the next
    connection. Its process is killed instead, and the next connection gets the registers."""
    import os

    robot = make_robot()
    in_contact(robot, skin)
    pid = robot._control.pid
    fire_after(0.3, lambda: loopback.drop_connections(refuse_for=0.0))
    with pytest.raises(RobotConnectionError):
        robot.press(0.001, 3.0)
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # gone (and reaped) the moment the link was found lost
    time.sleep(1.0)  # time for any reconnect attempt to show
    assert not loopback.state()["connections"].get("rtde")
    robot.close()
    robot.connect()  # "input registers already in use" if anything had reconnected
    robot.move_above(PLACEMENT, 0.01)


def _gone(pid: int) -> str:
    """ "gone", or "Z" for a zombie nobody reaps (an orphan's new parent may be a container's
    init): either way the process runs no more."""
    from pathlib import Path

    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return "gone"


@pytest.mark.parametrize("stuck", [False, True], ids=["idle", "stuck-in-a-call"])
def test_the_control_process_ends_with_ours(make_robot, loopback, stuck):
    """SIGKILL cannot be caught: the control client's process must not outlive us, keeping the
    controller's registers and feeding its watchdog — idle, or stuck in a call on a frozen
    network (ur_rtde waits up to 300 s there)."""
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    loopback.reset()
    script = (
        "import sys, time\n"
        "from aptkt.robot import UR10\n"
        f"robot = UR10({loopback.host!r})\n"
        "print(robot._control.pid, flush=True)\n"
        "sys.stdin.readline()\n"
        "pose = list(robot._link.peek_pose())\n"
        "robot._link.control.request('moveL', pose, 0.01, 0.1, False)\n"
        "print('sent', flush=True)\n"
        "time.sleep(60)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2] / "python")}
    proc = subprocess.Popen(
        [sys.executable, "-c", script],
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        child = int(proc.stdout.readline())
        assert loopback.state()["connections"].get("rtde") == 2
        if stuck:
            loopback.freeze()
            proc.stdin.write("go\n")
            proc.stdin.flush()
            assert proc.stdout.readline() == "sent\n"
            time.sleep(0.3)  # the call waits for a "done" that never comes
            assert _gone(child) not in ("gone", "Z", "X")
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    try:
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline and _gone(child) not in ("gone", "Z", "X"):
            time.sleep(0.05)
        assert _gone(child) in ("gone", "Z", "X")
    finally:
        loopback.freeze(False)
    deadline = time.monotonic() + 3.0
    while time.monotonic() < deadline and loopback.state()["connections"].get("rtde"):
        time.sleep(0.05)
    assert not loopback.state()["connections"].get("rtde")
