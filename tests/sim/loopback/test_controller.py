"""The simulated controller on its own: the control-script handshake, motion, force mode, faults.

These drive :class:`SimulatedController` cycle by cycle, writing the RTDE input registers as
ur_rtde's client would, so they need neither sockets nor ur_rtde.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aptkt.sim.loopback import ControllerConfig, SimulatedController, SpringSurface
from aptkt.sim.loopback import contact as contact_models
from aptkt.sim.loopback.config import PAUSED, PLAYING, STOPPED
from aptkt.sim.loopback.rotvec import (
    integrate_rotvec,
    interpolate_rotvec,
    matrix_to_rotvec,
    rotvec_to_matrix,
)
from aptkt.sim.loopback.script import DONE_WITH_CMD, RDY_FOR_CMD

DOWN = (math.pi, 0.0, 0.0)
# The lines of ur_rtde's uploaded script the loopback relies on (name, offsets injection).
SCRIPT = (
    "def rtde_control():\n# HEADER_BEGIN\n    global reg_offset_float = # float register offset\n"
    "{off}    global reg_offset_int = # int register offset\n{off}    global x = 0\n"
    "    def signal_ready():\n        write_output_integer_reg(0, 1)\n    end\nend\n"
)


def controller(offset: int = 0, pose=(0.0, -0.5, 0.01, *DOWN), **config) -> SimulatedController:
    ctl = SimulatedController(ControllerConfig(start_pose=pose, **config))
    ctl.load_script(SCRIPT.format(off=offset), 30003)
    return ctl


def send(ctl: SimulatedController, cmd: int, ints=(), doubles=(), offset: int = 0) -> None:
    values: dict[str, float] = {f"input_int_register_{offset}": cmd}
    values.update({f"input_int_register_{offset + 1 + i}": v for i, v in enumerate(ints)})
    values.update({f"input_double_register_{offset + i}": v for i, v in enumerate(doubles)})
    ctl.apply_inputs(values)


def ticks_until(ctl: SimulatedController, done, limit: int = 5000) -> int:
    for n in range(1, limit + 1):
        ctl.tick()
        if done():
            return n
    raise AssertionError("condition not reached")


def movel(ctl, pose, v, a, asynchronous=False, offset=0):
    send(ctl, 3, ints=[1 if asynchronous else 0], doubles=[*pose, v, a], offset=offset)


@pytest.mark.parametrize("offset", [0, 24])
def test_the_uploaded_script_starts_ready_with_its_register_offset(offset):
    ctl = controller(offset)
    assert ctl.runtime_state == PLAYING and ctl.program.name == "rtde_control"
    assert (ctl.program.int_offset, ctl.program.float_offset) == (offset, offset)
    assert ctl.output_int[offset] == RDY_FOR_CMD
    movel(ctl, (0.0, -0.5, 0.02, *DOWN), 0.1, 1.0, offset=offset)
    ticks_until(ctl, lambda: ctl.output_int[offset] == DONE_WITH_CMD)
    assert ctl.pose[2] == pytest.approx(0.02, abs=1e-12)


def test_other_programs_do_not_run():
    ctl = SimulatedController()
    ctl.load_script("def my_program():\n  movej([0,0,0,0,0,0])\nend\n", 30002)
    assert ctl.runtime_state == STOPPED and ctl.program is None
    assert "cannot run program 'my_program'" in ctl.stop_reason


@settings(max_examples=25, deadline=None)
@given(
    length=st.floats(1e-4, 0.05),
    v=st.floats(0.005, 0.25),
    a=st.floats(0.1, 2.0),
    direction=st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda d: np.linalg.norm(d) > 0.1),
)
def test_synchronous_movel_follows_a_trapezoid_and_signals_done_on_arrival(length, v, a, direction):
    ctl = controller()
    d = np.asarray(direction) / np.linalg.norm(direction)
    start = ctl.pose.copy()
    target = start.copy()
    target[:3] += d * length
    movel(ctl, target, v, a)
    speeds = []
    n = ticks_until(
        ctl,
        lambda: (
            (speeds.append(np.linalg.norm(ctl.velocity[:3])) or True)
            and ctl.output_int[0] == DONE_WITH_CMD
        ),
    )
    np.testing.assert_allclose(ctl.pose[:3], target[:3], atol=1e-12)
    speeds = np.array(speeds)
    assert speeds.max() <= v + 1e-12
    steps = np.abs(np.diff(np.concatenate([[0.0], speeds])))
    # Every cycle changes the speed by at most a*dt; the last two (braking onto a target that
    # is no whole number of braking steps away, then landing) by at most 1.25 a*dt.
    assert np.all(steps[:-2] <= a * ctl.dt * (1 + 1e-9))
    assert np.all(steps[-2:] <= 1.25 * a * ctl.dt)
    # The path is a straight line.
    offsets = ctl.pose[:3] - start[:3]
    assert np.linalg.norm(np.cross(offsets, d)) < 1e-9
    # Duration of a trapezoid (or triangle) profile, within two cycles.
    t_ideal = length / v + v / a if length > v * v / a else 2 * math.sqrt(length / a)
    assert abs(n * ctl.dt - t_ideal) <= 2 * ctl.dt + 0.02 * t_ideal
    # The client clears the command register; the script answers "ready" again.
    send(ctl, 0)
    ctl.tick()
    assert ctl.output_int[0] == RDY_FOR_CMD


def test_asynchronous_movel_reports_progress_in_the_async_register():
    ctl = controller()
    before = ctl.output_int[2]
    movel(ctl, (0.0, -0.5, 0.015, *DOWN), 0.05, 1.0, asynchronous=True)
    ctl.tick()
    assert ctl.output_int[0] == DONE_WITH_CMD  # at once: the move runs in the background
    running = ctl.output_int[2]
    # bits 24-30 operation id, bit 15 running, bits 16-22 write counter
    assert (running >> 24) & 0x7F == ((before >> 24) & 0x7F) + 1 and running & 0x8000
    assert ctl.pose[2] < 0.015
    send(ctl, 0)
    ticks_until(ctl, lambda: not ctl.output_int[2] & 0x8000)
    finished = ctl.output_int[2]
    assert (finished >> 24) & 0x7F == (running >> 24) & 0x7F
    assert ((finished >> 16) & 0x7F) == ((running >> 16) & 0x7F) + 1
    assert ctl.pose[2] == pytest.approx(0.015, abs=1e-12)


def test_speedl_ramps_at_its_acceleration_and_speedstop_brings_it_to_rest():
    ctl = controller()
    send(ctl, 10, doubles=[0.02, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0])
    ctl.tick()
    assert ctl.output_int[0] == RDY_FOR_CMD  # a real-time command: no done handshake
    n = ticks_until(ctl, lambda: ctl.velocity[0] >= 0.02 - 1e-12)
    assert n * ctl.dt == pytest.approx(0.02 / 0.5, abs=2 * ctl.dt)
    send(ctl, 0)  # the command register may change: the speed thread keeps going
    for _ in range(10):
        ctl.tick()
    assert ctl.velocity[0] == pytest.approx(0.02)
    send(ctl, 15, doubles=[1.0])
    n = ticks_until(ctl, lambda: ctl.output_int[0] == DONE_WITH_CMD)
    assert not np.any(ctl.velocity) and n * ctl.dt == pytest.approx(0.02 / 1.0, abs=2 * ctl.dt)


@settings(max_examples=20, deadline=None)
@given(stiffness=st.floats(50.0, 1e5), target=st.floats(0.05, 2.0), gain=st.sampled_from([3, 5]))
def test_force_mode_settles_on_the_requested_force(stiffness, target, gain):
    # Start in light contact, as the backend does after its approach.
    start_z = -0.05 / stiffness
    ctl = controller(
        pose=(0.0, -0.5, start_z, *DOWN),
        contact={"type": "spring", "surface_z": 0.0, "stiffness": stiffness},
        version=(gain, 15, 8, 0),
    )
    send(
        ctl,
        6,
        ints=[2, 0, 0, 1, 0, 0, 0],
        doubles=[0, 0, 0, 0, 0, 0, 0, 0, -target, 0, 0, 0, 0.01, 0.01, 0.01, 0.1, 0.1, 0.1],
    )
    # Long enough to travel the indentation at the 1 cm/s speed limit, then to settle for six
    # time constants of the admittance loop (gain scaling 0.5 from PolyScope 5 on).
    cfg = ctl.config
    tau = 1.0 / (cfg.force_mode_admittance * (0.5 if gain == 5 else 1.0) * stiffness)
    seconds = (target / stiffness) / 0.01 + 6.0 * max(tau, 2 * ctl.dt) + 0.2
    forces = [ctl.normal_force() for _ in range(int(seconds / ctl.dt)) if ctl.tick() is None]
    assert forces[-1] == pytest.approx(target, rel=0.02)
    assert max(forces) <= target * 1.02 + 0.05  # no overshoot beyond the starting contact
    assert np.all(np.abs(ctl.velocity[:2]) == 0.0)
    # forceModeStop leaves force control and stops.
    send(ctl, 7)
    ticks_until(ctl, lambda: ctl.output_int[0] == DONE_WITH_CMD)
    assert ctl.force_mode is None and not np.any(ctl.velocity)


def test_friction_opposes_sliding_and_zero_ft_sensor_offsets_the_wrench():
    ctl = controller(
        pose=(0.0, -0.5, -0.001, *DOWN),
        contact={"type": "spring", "surface_z": 0.0, "stiffness": 200.0, "friction": 0.5},
    )
    ctl.tick()
    np.testing.assert_allclose(ctl.tcp_force[:3], [0.0, 0.0, 0.2])
    send(ctl, 8)
    ticks_until(ctl, lambda: ctl.output_int[0] == DONE_WITH_CMD)
    ctl.tick()
    np.testing.assert_allclose(ctl.tcp_force[:3], 0.0, atol=1e-15)
    send(ctl, 10, doubles=[0.01, 0, 0, 0, 0, 0, 1.0, 0.0])
    for _ in range(20):
        ctl.tick()
    np.testing.assert_allclose(ctl.external_force, [-0.1, 0.0, 0.2])


def test_controller_force_limit_triggers_a_protective_stop():
    ctl = controller(contact={"type": "spring", "surface_z": 0.0, "stiffness": 1e4})
    movel(ctl, (0.0, -0.5, -0.05, *DOWN), 0.1, 1.0)
    ticks_until(ctl, lambda: ctl.protective_stopped)
    assert ctl.runtime_state == PAUSED and not np.any(ctl.velocity) and ctl.motion is None
    assert "above the controller's 150.0 N limit" in ctl.protective_stop_reason
    assert ctl.normal_force() == pytest.approx(150.0, abs=1e4 * 0.1 * ctl.dt)
    assert ctl.output_values(["safety_status_bits", "robot_status_bits"]) == [4, 1]


def test_the_rtde_watchdog_stops_the_program():
    ctl = controller()
    send(ctl, 35, doubles=[50.0])  # setWatchdog(50 Hz)
    ctl.tick()
    send(ctl, 0)
    send(ctl, 10, doubles=[0.0, 0.01, 0, 0, 0, 0, 1.0, 0.0])
    ctl.tick()
    assert ctl.program_running
    time.sleep(0.03)  # no update of input_int_register_0 for longer than 1/50 s
    ctl.tick()
    assert ctl.runtime_state == STOPPED and not np.any(ctl.velocity)
    assert "RTDE input watchdog" in ctl.stop_reason and ctl.watchdog is None


def test_unsupported_commands_stop_the_program_like_a_script_error():
    ctl = controller()
    send(ctl, 1, doubles=[0, 0, 0, 0, 0, 0, 1.0, 1.0])  # moveJ: joint space is not simulated
    ctl.tick()
    assert ctl.runtime_state == STOPPED
    assert ctl.stop_reason == "script error: command 1 is not simulated by the loopback controller"


def test_stop_script_ends_the_program():
    ctl = controller()
    send(ctl, 255)
    ctl.tick()
    assert ctl.runtime_state == STOPPED and ctl.program is None


def test_disturbances_ramp_or_step_and_a_stop_command_ends_them():
    ctl = controller()
    ctl.disturb([0.0, 0.1, 0.0], duration=1.0, acceleration=1.0)
    ctl.tick()
    assert ctl.velocity[1] == pytest.approx(1.0 * ctl.dt)
    ctl.disturb([0.05, 0.0, 0.0], duration=1.0)
    ctl.tick()
    np.testing.assert_allclose(ctl.velocity[:3], [0.05, 0.0, 0.0])
    send(ctl, 33, ints=[0], doubles=[10.0])  # stopL
    ticks_until(ctl, lambda: ctl.output_int[0] == DONE_WITH_CMD)
    ctl.tick()
    assert not np.any(ctl.velocity)


def test_dashboard_answers_like_a_cb3_dashboard_server():
    ctl = controller(unlock_delay=0.05)
    assert ctl.dashboard("PolyscopeVersion") == "URSoftware 3.15.8.106339 (loopback)"
    assert ctl.dashboard("running") == "Program running: true"
    assert ctl.dashboard("programState") == "PLAYING rtde_control"
    assert ctl.dashboard("pause") == "Pausing program"
    assert ctl.dashboard("play") == "Starting program"
    ctl.trigger_protective_stop("test")
    assert ctl.dashboard("safetymode") == "Safetymode: PROTECTIVE_STOP"
    assert ctl.dashboard("unlock protective stop").startswith(
        "Cannot unlock protective stop until 5s"
    )
    time.sleep(0.06)
    assert ctl.dashboard("unlock protective stop") == "Protective stop releasing"
    assert ctl.dashboard("safetymode") == "Safetymode: NORMAL"
    assert ctl.dashboard("play") == "Starting program" and ctl.program_running
    assert ctl.dashboard("stop") == "Stopped" and ctl.runtime_state == STOPPED
    assert ctl.dashboard("stop") == "Failed to execute: stop"
    assert ctl.dashboard("teleport home") == "could not understand: 'teleport home'"
    assert ctl.dashboard("quit") is None


def test_spring_surface_and_contact_specs():
    s = SpringSurface(surface_z=0.01, stiffness=300.0, x_range=(-0.1, 0.1))
    assert s.normal_force((0.0, 0.0, 0.009)) == pytest.approx(0.3)
    assert s.normal_force((0.0, 0.0, 0.011)) == 0.0
    assert s.normal_force((0.2, 0.0, 0.0)) == 0.0  # off the footprint
    built = contact_models.build(
        {
            "factory": "aptkt.sim.loopback.contact:SpringSurface",
            "params": {"surface_z": 0.01, "stiffness": 300.0, "x_range": [-0.1, 0.1]},
        }
    )
    assert built == s
    assert contact_models.build(None).normal_force((0, 0, -1)) == 0.0
    with pytest.raises(ValueError, match="unknown type 'jelly'"):
        contact_models.build({"type": "jelly"})
    with pytest.raises(ValueError, match="factory must be 'module:attr'"):
        contact_models.build({"factory": "nocolon"})
    with pytest.raises(ValueError, match="stiffness must be a finite number > 0"):
        SpringSurface(stiffness=0.0)


rotvecs = st.tuples(*[st.floats(-3.0, 3.0)] * 3).filter(
    lambda r: np.linalg.norm(r) < math.pi - 1e-3
)


@given(rotvecs)
def test_rotation_vectors_round_trip(r):
    m = rotvec_to_matrix(np.array(r))
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(matrix_to_rotvec(m), r, atol=1e-9)


@given(rotvecs, rotvecs)
def test_orientation_interpolation_hits_both_ends(r0, r1):
    np.testing.assert_allclose(
        rotvec_to_matrix(interpolate_rotvec(np.array(r0), np.array(r1), 0.0)),
        rotvec_to_matrix(np.array(r0)),
        atol=1e-9,
    )
    np.testing.assert_allclose(
        rotvec_to_matrix(interpolate_rotvec(np.array(r0), np.array(r1), 1.0)),
        rotvec_to_matrix(np.array(r1)),
        atol=1e-9,
    )


def test_integrating_an_angular_velocity_rotates_about_the_base_axis():
    r = integrate_rotvec(np.zeros(3), np.array([0.0, 0.0, 1.0]), math.pi / 2)
    np.testing.assert_allclose(rotvec_to_matrix(r) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(matrix_to_rotvec(rotvec_to_matrix(np.array(DOWN))), DOWN, atol=1e-9)
