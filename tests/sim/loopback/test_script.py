"""The emulated ur_rtde control script on its own: the register handshake and each command,
against a host that records what it was asked to do (no controller, no motion)."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.sim.loopback.config import PLAYING, STOPPED
from aptkt.sim.loopback.motion import ForceMode
from aptkt.sim.loopback.registers import RtdeRegisters
from aptkt.sim.loopback.script import (
    DONE_WITH_CMD,
    RDY_FOR_CMD,
    SUPPORTED_COMMANDS,
    ControlScript,
    recognise,
)

SCRIPT = (
    "def rtde_control():\n# HEADER_BEGIN\n    global reg_offset_float = # float register offset\n"
    "{off}    global reg_offset_int = # int register offset\n{off}    global x = 0\nend\n"
)


class Host:
    """A controller stand-in: records every call; its motion runs until ``finish``."""

    def __init__(self, version: tuple[int, int] = (5, 11)):
        self.dt = 0.002
        self.runtime_state = PLAYING
        self.program: ControlScript | None = None
        self.version = version
        self.calls: list[tuple] = []
        self.running = False
        self.force_mode: ForceMode | None = None
        self.steady = True
        self.stopped: str | None = None

    def log(self, message):
        self.calls.append(("log", message))

    def at_least(self, major, minor):
        return self.version >= (major, minor)

    def move_linear(self, pose, v, a, asynchronous):
        self.running = True
        self.calls.append(("movel", pose.tolist(), v, a, asynchronous))

    def speed_linear(self, velocity, acceleration):
        self.calls.append(("speedl", velocity.tolist(), acceleration))

    def stop_linear(self, deceleration, asynchronous):
        self.running = True
        self.calls.append(("stopl", deceleration, asynchronous))

    def motion_running(self):
        return self.running

    def end_motion(self):
        self.calls.append(("end_motion",))

    def set_force_mode(self, mode):
        self.force_mode = mode

    def zero_ft_sensor(self):
        self.calls.append(("zero_ft",))

    def set_payload(self, mass, cog):
        self.calls.append(("payload", mass, cog))

    def set_tcp(self, offset):
        self.calls.append(("tcp", offset.tolist()))

    def target_waypoint(self):
        return np.arange(6.0)

    def protective_stop(self, reason):
        self.calls.append(("protective_stop", reason))

    def set_watchdog(self, variable, frequency):
        self.calls.append(("watchdog", variable, frequency))

    def is_steady(self):
        return self.steady

    def stop_program(self, reason):
        self.stopped = reason
        self.runtime_state = STOPPED
        self.program = None


def started(offset: int = 0, **host) -> tuple[ControlScript, RtdeRegisters, Host]:
    regs = RtdeRegisters()
    script = ControlScript(SCRIPT.format(off=f"    {offset}\n"), regs)
    h = Host(**host)
    h.program = script
    script.start()
    return script, regs, h


def command(regs, script, cmd, ints=(), doubles=()):
    regs.input_int[script.int_offset] = cmd
    for i, v in enumerate(ints):
        regs.input_int[script.int_offset + 1 + i] = v
    for i, v in enumerate(doubles):
        regs.input_double[script.float_offset + i] = v


def test_recognises_only_ur_rtdes_control_script():
    assert recognise(SCRIPT.format(off="")) == ("rtde_control", True)
    assert recognise("def rtde_control():\n  movej([0]*6)\nend\n") == ("rtde_control", False)
    assert recognise("def mine():\n  signal_ready()\nend\n") == ("mine", False)
    assert recognise("textmsg(1)\n") == ("<unnamed>", False)


@pytest.mark.parametrize("offset", [0, 24])
def test_start_reads_the_injected_offsets_and_signals_ready(offset):
    script, regs, _ = started(offset)
    assert (script.int_offset, script.float_offset) == (offset, offset)
    assert regs.output_int[offset] == RDY_FOR_CMD
    assert regs.output_int[offset + 2] & 0x8000 == 0  # no asynchronous operation running


def test_a_blocking_movel_answers_done_once_its_motion_ends():
    script, regs, host = started(24)
    command(regs, script, 3, ints=[0], doubles=[0.1, -0.5, 0.2, 3.14, 0, 0, 0.25, 1.2])
    script.cycle(host)
    assert host.calls == [("movel", [0.1, -0.5, 0.2, 3.14, 0.0, 0.0], 0.25, 1.2, False)]
    assert script.waiting == "motion" and regs.output_int[24] == RDY_FOR_CMD
    script.cycle(host)  # still moving: no answer
    assert regs.output_int[24] == RDY_FOR_CMD
    host.running = False
    script.cycle(host)
    assert regs.output_int[24] == DONE_WITH_CMD and host.calls[-1] == ("end_motion",)
    script.cycle(host)  # the command register still holds 3: it is not executed again
    assert [c[0] for c in host.calls].count("movel") == 1
    command(regs, script, 0)
    script.cycle(host)
    assert regs.output_int[24] == RDY_FOR_CMD and not script.executing


def test_an_asynchronous_movel_answers_at_once_and_reports_progress():
    script, regs, host = started()
    before = regs.output_int[2]
    command(regs, script, 3, ints=[1], doubles=[0, 0, 0, 0, 0, 0, 0.1, 1.0])
    script.cycle(host)
    assert regs.output_int[0] == DONE_WITH_CMD and script.waiting is None
    running = regs.output_int[2]
    assert running & 0x8000 and (running >> 24) & 0x7F == ((before >> 24) & 0x7F) + 1
    assert script.motion_finished(asynchronous=True) is False
    done = regs.output_int[2]
    assert not done & 0x8000 and (done >> 16) & 0x7F == ((running >> 16) & 0x7F) + 1


def test_real_time_commands_answer_ready_and_run_every_cycle():
    script, regs, host = started()
    command(regs, script, 10, doubles=[0.01, 0, 0, 0, 0, 0, 0.5])
    script.cycle(host)
    script.cycle(host)
    assert regs.output_int[0] == RDY_FOR_CMD and script.speeding
    assert host.calls == [("speedl", [0.01, 0, 0, 0, 0, 0], 0.5)] * 2
    command(
        regs,
        script,
        6,
        ints=[2, 0, 0, 1, 0, 0, 0],
        doubles=[0, 0, 0, 0, 0, 0, 0, 0, -1.5, 0, 0, 0, 0.01, 0.01, 0.02, 0.1, 0.1, 0.1],
    )
    script.cycle(host)
    mode = host.force_mode
    assert mode is not None and mode.type == 2 and mode.selection == [0, 0, 1, 0, 0, 0]
    assert mode.wrench[2] == -1.5 and mode.limits[2] == 0.02


def test_stop_commands_wait_for_the_stop_and_end_the_speed_thread():
    script, regs, host = started()
    script.speeding = True
    command(regs, script, 15, doubles=[2.5])
    script.cycle(host)
    assert host.calls == [("stopl", 2.5, False)] and not script.speeding
    assert script.waiting == "motion"
    script, regs, host = started()
    host.force_mode = object()
    command(regs, script, 7)
    script.cycle(host)
    assert host.force_mode is None and host.calls == [("stopl", 10.0, False)]


@pytest.mark.parametrize(("version", "answered"), [((5, 4), True), ((3, 15), False)])
def test_version_dependent_commands(version, answered):
    script, regs, host = started(version=version)
    command(regs, script, 26)
    script.cycle(host)
    assert regs.output_double[0] == (0.002 if answered else 0.0)
    command(regs, script, 0)
    script.cycle(host)
    command(regs, script, 28)
    script.cycle(host)
    assert regs.output_double[:6] == ([0.0, 1.0, 2.0, 3.0, 4.0, 5.0] if answered else [0.0] * 6)


def test_settings_commands_reach_the_host_or_the_script():
    script, regs, host = started()
    for cmd, doubles in (
        (17, [1.5, 0.0, 0.01, 0.02]),
        (29, [0, 0, 0.1, 0, 0, 0]),
        (20, [0.02]),
        (21, [0.7]),
        (35, [50.0]),
        (8, []),
        (31, []),
    ):
        command(regs, script, cmd, doubles=doubles)
        script.cycle(host)
        assert regs.output_int[0] == DONE_WITH_CMD, cmd
        command(regs, script, 0)
        script.cycle(host)
    assert ("payload", 1.5, [0.0, 0.01, 0.02]) in host.calls
    assert ("tcp", [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]) in host.calls
    assert ("watchdog", "input_int_register_0", 50.0) in host.calls
    assert ("zero_ft",) in host.calls
    assert ("protective_stop", "protective_stop() called by the program") in host.calls
    assert (script.damping, script.gain_scaling) == (0.02, 0.7)


def test_is_steady_answers_in_its_output_register():
    script, regs, host = started()
    for steady in (True, False):
        host.steady = steady
        command(regs, script, 47)
        script.cycle(host)
        assert regs.output_int[1] == int(steady)
        command(regs, script, 0)
        script.cycle(host)


def test_stop_script_and_unknown_commands_end_the_program():
    script, regs, host = started()
    command(regs, script, 255)
    script.cycle(host)
    assert host.stopped == "stopScript received"
    script, regs, host = started()
    command(regs, script, 4)  # moveJ: joint space is not simulated
    script.cycle(host)
    assert host.stopped == "script error: command 4 is not simulated by the loopback controller"
    assert 4 not in SUPPORTED_COMMANDS


def test_a_protective_stop_releases_a_waiting_command():
    script, regs, host = started()
    command(regs, script, 3, ints=[0], doubles=[0, 0, 0, 0, 0, 0, 0.1, 1.0])
    script.cycle(host)
    script.interrupted()
    assert script.waiting is None and script.executing
    script.cycle(host)  # the command register still holds moveL: not started again
    assert [c[0] for c in host.calls].count("movel") == 1
