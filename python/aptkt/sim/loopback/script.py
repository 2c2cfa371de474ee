"""The URScript the controller runs: ur_rtde's control script, recognised when it is uploaded
and emulated command by command (it is not a general URScript interpreter).

The real ur_rtde client uploads a URScript program (``def rtde_control(): ...``) to the
script port. That program loops once per control cycle: it reads a command number from
``input_int_register_0`` (+ offset 0 or 24), reads arguments from the input int/double
registers, executes, and answers through ``output_int_register_0``: 1 = ready for a command,
2 = done with the command (the client then writes 0 and the script answers 1 again).
"Real-time" commands (speedL, forceMode, servo*, ...) answer 1 right after processing.
:class:`ControlScript` emulates that loop for the commands listed in
:data:`SUPPORTED_COMMANDS` against a :class:`ScriptHost` (the controller); any other command
stops the program as a script runtime error would, so a client never hangs on it silently.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from typing import Protocol

import numpy as np

from aptkt.sim.loopback.config import PLAYING
from aptkt.sim.loopback.motion import ForceMode
from aptkt.sim.loopback.registers import RtdeRegisters

__all__ = [
    "ControlScript",
    "DONE_WITH_CMD",
    "RDY_FOR_CMD",
    "SUPPORTED_COMMANDS",
    "ScriptError",
    "ScriptHost",
    "recognise",
]

RDY_FOR_CMD, DONE_WITH_CMD = 1, 2

#: ur_rtde command numbers the emulated control script executes.
SUPPORTED_COMMANDS: Mapping[int, str] = {
    0: "no command / kickWatchdog",
    3: "moveL (synchronous and asynchronous)",
    6: "forceMode",
    7: "forceModeStop",
    8: "zeroFtSensor",
    10: "speedL",
    15: "speedStop",
    17: "setPayload",
    20: "forceModeSetDamping",
    21: "forceModeSetGainScaling",
    26: "getStepTime",
    28: "getTargetWaypoint",
    29: "setTcp",
    31: "triggerProtectiveStop",
    33: "stopL (synchronous and asynchronous)",
    34: "stopJ (executed as a Cartesian stop)",
    35: "setWatchdog",
    47: "isSteady",
    255: "stopScript",
}

# Commands the script answers with "ready" instead of "done" (they never block the client).
_REALTIME = {24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71}


class ScriptError(Exception):
    """The emulated control script cannot execute a command (a URScript runtime error)."""


class ScriptHost(Protocol):
    """What the control script commands: the controller's arm, force mode, sensors and
    program state."""

    dt: float
    runtime_state: int
    program: ControlScript | None

    def log(self, message: str) -> None: ...

    def at_least(self, major: int, minor: int) -> bool: ...

    def move_linear(self, pose: np.ndarray, v: float, a: float, asynchronous: bool) -> None: ...

    def speed_linear(self, velocity: np.ndarray, acceleration: float) -> None: ...

    def stop_linear(self, deceleration: float, asynchronous: bool) -> None: ...

    def motion_running(self) -> bool:
        """Whether the motion a blocking command waits for still runs."""
        ...

    def end_motion(self) -> None: ...

    def set_force_mode(self, mode: ForceMode | None) -> None: ...

    def zero_ft_sensor(self) -> None: ...

    def set_payload(self, mass: float, cog: list[float]) -> None: ...

    def set_tcp(self, offset: np.ndarray) -> None: ...

    def target_waypoint(self) -> np.ndarray: ...

    def protective_stop(self, reason: str) -> None: ...

    def set_watchdog(self, variable: str, frequency: float) -> None: ...

    def is_steady(self) -> bool: ...

    def stop_program(self, reason: str) -> None: ...


def recognise(text: str) -> tuple[str, bool]:
    """A program's name and whether it is ur_rtde's control script (the one program the
    controller runs)."""
    name_match = re.match(r"\s*(?:def|sec)\s+(\w+)\s*\(", text)
    name = name_match.group(1) if name_match else "<unnamed>"
    control = name == "rtde_control" and ("# HEADER_BEGIN" in text or "signal_ready" in text)
    return name, control


def _injected_offset(text: str, kind: str) -> int:
    """Register offset ur_rtde injects after ``# int register offset`` / ``# float ...``."""
    m = re.search(rf"reg_offset_{kind}\s*=\s*(?:#[^\n]*\n\s*)?(\d+)", text)
    if m:
        return int(m.group(1))
    m = re.search(rf"# {kind} register offset\n\s*(\d+)", text)
    return int(m.group(1)) if m else 0


class ControlScript:
    """State of the emulated ur_rtde control script and its main loop (:meth:`cycle`)."""

    def __init__(self, text: str, registers: RtdeRegisters, gain_scaling: float = 1.0):
        self.name, _ = recognise(text)
        self.int_offset = _injected_offset(text, "int")
        self.float_offset = _injected_offset(text, "float")
        self.registers = registers
        self.executing = False
        self.waiting: str | None = None  # what a blocking command waits for: "motion"
        self.async_wr_count = 0
        self.async_op_id = 0
        self.async_move = False
        self.speeding = False
        self.gain_scaling = gain_scaling
        self.damping = 0.005
        self._commands: dict[int, Callable[[ScriptHost], None]] = {
            3: self._move_linear,
            6: self._force_mode,
            7: self._force_mode_stop,
            8: lambda host: host.zero_ft_sensor(),
            10: self._speed_linear,
            15: self._speed_stop,
            17: lambda host: host.set_payload(
                self._in_float(0), [self._in_float(1), self._in_float(2), self._in_float(3)]
            ),
            20: self._set_damping,
            21: self._set_gain_scaling,
            26: self._step_time,
            28: self._target_waypoint,
            29: lambda host: host.set_tcp(self._in_vec6(0)),
            31: self._protective_stop,
            33: self._stop_linear,
            34: self._stop_linear,
            35: self._set_watchdog,
            47: lambda host: self._out_int(1, 1 if host.is_steady() else 0),
        }

    # -------------------------------------------------------------- registers at the offsets
    def _in_int(self, i: int) -> int:
        return self.registers.input_int[self.int_offset + i]

    def _in_float(self, i: int) -> float:
        return self.registers.input_double[self.float_offset + i]

    def _in_vec6(self, i: int) -> np.ndarray:
        return np.array([self._in_float(i + k) for k in range(6)])

    def _out_int(self, i: int, value: int) -> None:
        self.registers.output_int[self.int_offset + i] = int(value)

    def _out_float(self, i: int, value: float) -> None:
        self.registers.output_double[self.float_offset + i] = float(value)

    def start(self) -> None:
        """The script's first lines: no asynchronous operation, ready for a command."""
        self.write_async(-1)
        self._out_int(0, RDY_FOR_CMD)

    def write_async(self, value: int) -> None:
        """The script's write_async_progress_register (bit layout from ur_rtde's script)."""
        self.async_wr_count = (self.async_wr_count + 1) % 128
        if value == 0:
            self.async_op_id = (self.async_op_id + 1) % 128
        reg = self.async_wr_count * 65536 + self.async_op_id * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self._out_int(2, reg)

    # -------------------------------------------------------------- the main loop
    def cycle(self, host: ScriptHost) -> None:
        """One pass of the control script's main loop (it runs once per control cycle)."""
        if self.waiting == "motion":
            if host.motion_running():
                return  # the script is inside a blocking movel/stopl
            self.waiting = None
            host.end_motion()
            self._out_int(0, DONE_WITH_CMD)
            return
        cmd = self._in_int(0)
        try:
            if cmd in _REALTIME:
                self.execute(cmd, host)
                self._out_int(0, RDY_FOR_CMD)
            elif cmd == 0:
                self.executing = False
                self._out_int(0, RDY_FOR_CMD)
            elif not self.executing:
                self.executing = True
                keep_running = self.execute(cmd, host)
                if not keep_running:
                    host.stop_program("stopScript received")
                elif (
                    self.waiting is None and host.program is self and host.runtime_state == PLAYING
                ):
                    self._out_int(0, DONE_WITH_CMD)
        except ScriptError as exc:
            host.stop_program(f"script error: {exc}")

    def execute(self, cmd: int, host: ScriptHost) -> bool:
        """Execute one command; returns False for stopScript (the script's loop ends)."""
        if cmd == 255:
            host.log("Received stop script!")
            return False
        command = self._commands.get(cmd)
        if command is None:
            raise ScriptError(f"command {cmd} is not simulated by the loopback controller")
        command(host)
        return True

    def motion_finished(self, asynchronous: bool) -> bool:
        """A motion ended; returns whether a blocking command waits for it."""
        if asynchronous and self.async_move:
            self.async_move = False
            self.write_async(-1)
        return self.waiting == "motion"

    def interrupted(self) -> None:
        """A protective stop: a blocking command no longer waits, and the script takes no
        new command until the client clears the register."""
        self.waiting = None
        self.executing = True

    def _stop_async_move(self) -> None:
        if self.async_move:
            self.async_move = False
            self.write_async(-1)

    # -------------------------------------------------------------- the commands
    def _move_linear(self, host: ScriptHost) -> None:
        pose = self._in_vec6(0)
        v, a = self._in_float(6), self._in_float(7)
        asynchronous = self._in_int(1) == 1
        self._stop_async_move()
        host.move_linear(pose, v, a, asynchronous)
        if asynchronous:
            self.async_move = True
            self.write_async(0)
        else:
            self.waiting = "motion"

    def _stop_linear(self, host: ScriptHost) -> None:
        decel = self._in_float(0)
        asynchronous = self._in_int(1) == 1
        self._stop_async_move()
        host.stop_linear(decel, asynchronous)
        if asynchronous:
            self.async_move = True
            self.write_async(0)
        else:
            self.waiting = "motion"

    def _force_mode(self, host: ScriptHost) -> None:
        mode = ForceMode(
            frame=self._in_vec6(0),
            selection=[self._in_int(2 + k) for k in range(6)],
            wrench=self._in_vec6(6),
            limits=self._in_vec6(12),
            type=self._in_int(1),
        )
        host.set_force_mode(mode)
        if mode.type != 2:
            host.log(f"force mode type {mode.type} simulated as type 2 (frame not transformed)")

    def _force_mode_stop(self, host: ScriptHost) -> None:
        host.set_force_mode(None)
        host.stop_linear(10.0, False)
        self.waiting = "motion"

    def _speed_linear(self, host: ScriptHost) -> None:
        host.speed_linear(self._in_vec6(0), self._in_float(6))
        self.speeding = True

    def _speed_stop(self, host: ScriptHost) -> None:
        self.speeding = False
        host.stop_linear(self._in_float(0), False)
        self.waiting = "motion"

    def _set_damping(self, host: ScriptHost) -> None:
        self.damping = self._in_float(0)

    def _set_gain_scaling(self, host: ScriptHost) -> None:
        self.gain_scaling = self._in_float(0)

    def _step_time(self, host: ScriptHost) -> None:
        # get_steptime() exists from PolyScope 5.4; ur_rtde strips the call on older versions.
        if host.at_least(5, 4):
            self._out_float(0, host.dt)

    def _target_waypoint(self, host: ScriptHost) -> None:
        if host.at_least(5, 3):
            target = host.target_waypoint()
            for k in range(6):
                self._out_float(k, float(target[k]))

    def _protective_stop(self, host: ScriptHost) -> None:
        if host.at_least(3, 8):
            host.protective_stop("protective_stop() called by the program")

    def _set_watchdog(self, host: ScriptHost) -> None:
        freq = self._in_float(0)
        variable = f"input_int_register_{self.int_offset}"
        host.set_watchdog(variable, freq)
        host.log(f"rtde watchdog on {variable} at {freq} Hz")
