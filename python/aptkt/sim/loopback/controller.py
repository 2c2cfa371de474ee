"""A simulated UR controller: Cartesian TCP motion, contact wrench, RTDE registers and the
register handshake of ur_rtde's control script.

The real ur_rtde client uploads a URScript program (``def rtde_control(): ...``) to the
script port. That program loops once per control cycle: it reads a command number from
``input_int_register_0`` (+ offset 0 or 24), reads arguments from the input int/double
registers, executes, and answers through ``output_int_register_0``: 1 = ready for a command,
2 = done with the command (the client then writes 0 and the script answers 1 again).
"Real-time" commands (speedL, forceMode, servo*, ...) answer 1 right after processing.
This module does not interpret URScript: it recognises the uploaded ur_rtde program and
emulates that loop for the commands listed in :data:`SUPPORTED_COMMANDS`. Any other command
stops the program as a script runtime error would, so a client never hangs on it silently.

All methods are called with :attr:`SimulatedController.lock` held by the servers; the tick
advances the simulation by one control period.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt.sim.loopback import contact as contact_models
from aptkt.sim.loopback.rotvec import (
    integrate_rotvec,
    interpolate_rotvec,
    limit_norm,
    rotvec_to_matrix,
)
from aptkt.sim.loopback.rtde import input_type, output_type
from aptkt.sim.loopback.tcp_skin import SimulatedSkin, SkinConfig
from aptkt.sim.physics import GRAVITY

__all__ = [
    "ControllerConfig",
    "SimulatedController",
    "SUPPORTED_COMMANDS",
    "CB3_VERSION",
    "E_SERIES_VERSION",
]

CB3_VERSION = (3, 15, 8, 106339)
E_SERIES_VERSION = (5, 11, 6, 108249)

# Runtime states, robot modes and safety modes as the controller reports them over RTDE.
STOPPING, STOPPED, PLAYING, PAUSING, PAUSED, RESUMING = 0, 1, 2, 3, 4, 5
ROBOT_MODE_POWER_OFF, ROBOT_MODE_IDLE, ROBOT_MODE_RUNNING = 3, 5, 7
SAFETY_NORMAL, SAFETY_PROTECTIVE_STOP = 1, 3

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

_HOME_Q = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)


@dataclass
class ControllerConfig:
    """Everything that shapes one simulated controller. JSON-able (it crosses a process pipe)."""

    version: tuple[int, int, int, int] = CB3_VERSION
    start_pose: tuple[float, ...] = (0.0, -0.5, 0.2, math.pi, 0.0, 0.0)
    contact: dict[str, Any] | None = None
    #: Controller-side force limit; above it the controller protective-stops (UR default 150 N).
    protective_force_limit: float = 150.0
    #: Seconds after a protective stop before the dashboard accepts "unlock protective stop"
    #: (5 s on a real controller).
    unlock_delay: float = 5.0
    #: Gaussian noise (N) on the reported TCP force; CB3 estimates it from motor currents.
    force_noise: float = 0.0
    #: Force-mode admittance: TCP speed (m/s) per newton of force error, before gain scaling.
    force_mode_admittance: float = 0.05
    #: Acceleration cap (m/s^2) of the force-controlled axes.
    force_mode_acceleration: float = 0.25
    serial_number: str = "2017300000"
    robot_model: str = "UR10"
    seed: int = 0
    #: The simulated skin patch on the TCP, streamed through a pty (None: no skin). ``{}``
    #: for the defaults, or fields of :class:`aptkt.sim.loopback.tcp_skin.SkinConfig`.
    skin: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        self.version = tuple(int(v) for v in self.version)  # type: ignore[assignment]
        if len(self.version) != 4:
            raise ValueError(f"version must have 4 numbers, got {self.version!r}")
        self.start_pose = tuple(float(v) for v in self.start_pose)
        if len(self.start_pose) != 6:
            raise ValueError("start_pose must be [x, y, z, rx, ry, rz]")

    @property
    def frequency(self) -> float:
        """125 Hz for CB3 (major version 3), 500 Hz for e-Series."""
        return 125.0 if self.version[0] <= 3 else 500.0

    @property
    def polyscope_version(self) -> str:
        return ".".join(str(v) for v in self.version)


@dataclass
class _Motion:
    """A Cartesian motion generator. ``step`` returns the linear velocity for this cycle."""

    kind: str  # "movel" | "speedl" | "stop"
    velocity: float = 0.0  # movel: max speed; stop: unused
    acceleration: float = 1.0
    target: np.ndarray | None = None  # movel target pose / speedl target velocity (6)
    start: np.ndarray | None = None
    length: float = 0.0
    progress: float = 0.0
    speed: float = 0.0
    done: bool = False
    asynchronous: bool = False


@dataclass
class _ForceMode:
    frame: np.ndarray  # task frame pose (6)
    selection: list[int]
    wrench: np.ndarray
    limits: np.ndarray
    type: int


@dataclass
class _Watchdog:
    variable: str
    min_frequency: float
    action: str  # "ignore" | "pause" | "stop"
    last_update: float


@dataclass
class _ControlProgram:
    """State of the emulated ur_rtde control script."""

    name: str
    int_offset: int
    float_offset: int
    executing: bool = False
    waiting: str | None = None  # what a blocking command waits for: "motion"
    async_wr_count: int = 0
    async_op_id: int = 0
    async_move: bool = False
    speeding: bool = False
    gain_scaling: float = 1.0
    damping: float = 0.005


class ScriptError(Exception):
    """The emulated control script cannot execute a command (a URScript runtime error)."""


class SimulatedController:
    """One simulated UR controller. Thread-safe through :attr:`lock` (held by every caller)."""

    #: Controller time (s since "boot"); survives reset().
    time: float

    def __init__(self, config: ControllerConfig | None = None):
        self.config = config or ControllerConfig()
        self.lock = threading.RLock()
        self.dt = 1.0 / self.config.frequency
        self._rng = np.random.default_rng(self.config.seed)
        self.contact = contact_models.build(self.config.contact)
        self.text_log: deque[tuple[float, str]] = deque(maxlen=500)
        self.received_scripts: deque[str] = deque(maxlen=8)
        self.input_int = [0] * 48
        self.input_double = [0.0] * 48
        self.output_int = [0] * 48
        self.output_double = [0.0] * 48
        self.input_bits = [False] * 128
        self.output_bits = [False] * 128
        self.external_force_torque = [0.0] * 6
        self._input_owner: dict[str, int] = {}
        self.skin: Any = None
        if self.config.skin is not None:
            self.skin = SimulatedSkin(SkinConfig.from_spec(self.config.skin))
        self._skin_errors = 0
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, pose: Sequence[float] | None = None, keep_program: bool = False) -> None:
        """Back to a clean state: pose, no motion, no fault. The program survives if asked."""
        with self.lock:
            self.time = 0.0 if not hasattr(self, "time") else self.time
            self.pose = np.array(pose if pose is not None else self.config.start_pose, dtype=float)
            self.velocity = np.zeros(6)
            self.motion: _Motion | None = None
            self.force_mode: _ForceMode | None = None
            self.ft_offset = np.zeros(6)
            self.external_force = np.zeros(3)
            self.tcp_force = np.zeros(6)
            self.target_waypoint = self.pose.copy()
            self.robot_mode = ROBOT_MODE_RUNNING
            self.safety_mode = SAFETY_NORMAL
            self.protective_stop_time: float | None = None
            self.protective_stop_reason = ""
            self.tcp_offset = np.zeros(6)
            self._clear_disturbance()
            self.payload = (0.0, [0.0, 0.0, 0.0])
            if not keep_program or getattr(self, "program", None) is None:
                self.program: _ControlProgram | None = None
                self.runtime_state = STOPPED
                self.watchdog: _Watchdog | None = None
                self.output_int[0] = 0
            self.stop_reason = ""

    @property
    def program_running(self) -> bool:
        return self.runtime_state == PLAYING

    @property
    def protective_stopped(self) -> bool:
        return self.safety_mode == SAFETY_PROTECTIVE_STOP

    def log(self, message: str) -> None:
        self.text_log.append((self.time, message))

    def snapshot(self) -> dict[str, Any]:
        """A JSON-able view of the controller for tests and users."""
        with self.lock:
            return {
                "time": self.time,
                "pose": self.pose.tolist(),
                "velocity": self.velocity.tolist(),
                "tcp_force": self.tcp_force.tolist(),
                "external_force": self.external_force.tolist(),
                "normal_force": self.normal_force(),
                "runtime_state": self.runtime_state,
                "program_running": self.program_running,
                "program": None if self.program is None else self.program.name,
                "protective_stopped": self.protective_stopped,
                "protective_stop_reason": self.protective_stop_reason,
                "stop_reason": self.stop_reason,
                "robot_mode": self.robot_mode,
                "force_mode": self.force_mode is not None,
                "motion": None if self.motion is None else self.motion.kind,
                "watchdog": None
                if self.watchdog is None
                else {
                    "variable": self.watchdog.variable,
                    "min_frequency": self.watchdog.min_frequency,
                    "action": self.watchdog.action,
                },
                "moving": bool(np.any(np.abs(self.velocity) > 1e-9)),
                "skin": None if self.skin is None else self.skin.stats(),
                "text_log": [m for _, m in list(self.text_log)[-40:]],
            }

    def normal_force(self) -> float:
        return float(self.contact.normal_force(self.pose))

    def set_contact(self, spec: Mapping[str, Any] | None) -> None:
        with self.lock:
            self.contact = contact_models.build(spec)
            self.config.contact = None if spec is None else dict(spec)

    # ------------------------------------------------------------------ faults
    def trigger_protective_stop(self, reason: str) -> None:
        """Category-2-like stop: motion halts now, the program pauses, safety reports it."""
        with self.lock:
            if self.protective_stopped:
                return
            self._halt()
            self.safety_mode = SAFETY_PROTECTIVE_STOP
            self.protective_stop_time = time.monotonic()
            self.protective_stop_reason = reason
            self.log(f"protective stop: {reason}")
            if self.runtime_state == PLAYING:
                self.runtime_state = PAUSED
                if self.program is not None:
                    self.program.waiting = None
                    self.program.executing = True

    def stop_program(self, reason: str) -> None:
        """The program ends (pendant stop, dashboard ``stop``, watchdog, script error)."""
        with self.lock:
            if self.program is None and self.runtime_state == STOPPED:
                return
            self._halt()
            self.runtime_state = STOPPED
            self.program = None
            self.watchdog = None  # "All watchdogs are removed on program stop."
            self.stop_reason = reason
            self.log(f"program stopped: {reason}")

    def _halt(self) -> None:
        self.motion = None
        self.force_mode = None
        self.velocity = np.zeros(6)
        self._clear_disturbance()

    def _clear_disturbance(self) -> None:
        self.disturbance_target = np.zeros(3)
        self.disturbance_velocity = np.zeros(3)
        self.disturbance_acceleration = math.inf
        self.disturbance_until = 0.0

    def disturb(
        self, velocity: Sequence[float], duration: float, acceleration: float | None = None
    ) -> None:
        """An external push (or a misbehaving controller): the TCP gets an extra base-frame
        velocity, reached at ``acceleration`` (None: at once), for ``duration`` seconds."""
        with self.lock:
            self.disturbance_target = np.asarray(velocity, dtype=float)[:3]
            self.disturbance_acceleration = (
                math.inf if acceleration is None else float(acceleration)
            )
            self.disturbance_until = self.time + float(duration)
            self.log(f"disturbance {self.disturbance_target.tolist()} m/s for {duration} s")

    # ------------------------------------------------------------------ RTDE registers
    def claim_inputs(self, conn_id: int, names: Sequence[str]) -> list[str]:
        """Types for an input recipe; a variable another connection writes is ``IN_USE``."""
        with self.lock:
            types = []
            for name in names:
                t = input_type(name)
                if t is None:
                    types.append("NOT_FOUND")
                elif self._input_owner.get(name, conn_id) != conn_id:
                    types.append("IN_USE")
                else:
                    types.append(t)
            if all(t not in ("NOT_FOUND", "IN_USE") for t in types):
                for name in names:
                    self._input_owner[name] = conn_id
            return types

    def release_inputs(self, conn_id: int) -> None:
        with self.lock:
            for name in [n for n, owner in self._input_owner.items() if owner == conn_id]:
                del self._input_owner[name]

    def apply_inputs(self, values: Mapping[str, Any]) -> None:
        now = time.monotonic()
        with self.lock:
            for name, value in values.items():
                if name.startswith("input_int_register_"):
                    self.input_int[int(name.rsplit("_", 1)[1])] = int(value)
                elif name.startswith("input_double_register_"):
                    self.input_double[int(name.rsplit("_", 1)[1])] = float(value)
                elif name.startswith("input_bit_register_"):
                    self.input_bits[int(name.rsplit("_", 1)[1])] = bool(value)
                elif name == "external_force_torque":
                    self.external_force_torque = [float(v) for v in value]
                if self.watchdog is not None and self.watchdog.variable == name:
                    self.watchdog.last_update = now

    def output_values(self, names: Iterable[str]) -> list[Any]:
        with self.lock:
            return [self._output(name) for name in names]

    def _output(self, name: str) -> Any:
        if name.startswith("output_int_register_"):
            return self.output_int[int(name.rsplit("_", 1)[1])]
        if name.startswith("output_double_register_"):
            return self.output_double[int(name.rsplit("_", 1)[1])]
        if name.startswith("input_int_register_"):
            return self.input_int[int(name.rsplit("_", 1)[1])]
        if name.startswith("input_double_register_"):
            return self.input_double[int(name.rsplit("_", 1)[1])]
        if name.startswith("output_bit_register_"):
            return self.output_bits[int(name.rsplit("_", 1)[1])]
        if name.startswith("input_bit_register_"):
            return self.input_bits[int(name.rsplit("_", 1)[1])]
        running = self.program_running
        power = self.robot_mode != ROBOT_MODE_POWER_OFF
        table: dict[str, Any] = {
            "timestamp": self.time,
            "actual_TCP_pose": self.pose.tolist(),
            "target_TCP_pose": self.pose.tolist(),
            "actual_TCP_speed": self.velocity.tolist(),
            "target_TCP_speed": self.velocity.tolist(),
            "actual_TCP_force": self.tcp_force.tolist(),
            "ft_raw_wrench": (self.tcp_force + self.ft_offset).tolist(),
            "tcp_force_scalar": float(np.linalg.norm(self.tcp_force[:3])),
            "robot_mode": self.robot_mode,
            "safety_mode": self.safety_mode,
            "safety_status": self.safety_mode,
            "runtime_state": self.runtime_state,
            "robot_status_bits": (1 if power else 0) | (2 if running else 0),
            "safety_status_bits": (1 if self.safety_mode == SAFETY_NORMAL else 0)
            | (4 if self.protective_stopped else 0),
            "joint_mode": [253] * 6,
            "speed_scaling": 1.0,
            "target_speed_fraction": 1.0,
            "actual_tool_accelerometer": [0.0, 0.0, -GRAVITY],
            "joint_temperatures": [30.0] * 6,
            "actual_main_voltage": 48.0,
            "actual_robot_voltage": 48.0,
            "actual_joint_voltage": [48.0] * 6,
            "actual_execution_time": 0.5,
            "payload": self.payload[0],
            "payload_cog": list(self.payload[1]),
            "target_q": list(_HOME_Q),
            "actual_q": list(_HOME_Q),
        }
        if name in table:
            return table[name]
        t = output_type(name)
        zero = {
            "VECTOR3D": [0.0] * 3,
            "VECTOR6D": [0.0] * 6,
            "VECTOR6INT32": [0] * 6,
            "VECTOR6UINT32": [0] * 6,
            "DOUBLE": 0.0,
            "BOOL": False,
        }
        return zero.get(t or "", 0)

    # ------------------------------------------------------------------ programs
    def load_script(self, text: str, port: int) -> None:
        """A complete program arrived on a script port: it replaces the running program."""
        with self.lock:
            self.received_scripts.append(text)
            name_match = re.match(r"\s*(?:def|sec)\s+(\w+)\s*\(", text)
            name = name_match.group(1) if name_match else "<unnamed>"
            if self.program is not None or self.runtime_state != STOPPED:
                self.stop_program(f"replaced by a new program from port {port}")
            if self.robot_mode != ROBOT_MODE_RUNNING:
                self.log(
                    f"program {name} not started: robot is not running (mode {self.robot_mode})"
                )
                return
            if self.protective_stopped:
                self.log(f"program {name} not started: protective stop")
                return
            if (
                name != "rtde_control"
                or "# HEADER_BEGIN" not in text
                and "signal_ready" not in text
            ):
                self.stop_reason = (
                    f"loopback cannot run program {name!r} (only ur_rtde's control script)"
                )
                self.log(self.stop_reason)
                return
            int_offset = _injected_offset(text, "int")
            float_offset = _injected_offset(text, "float")
            self.program = _ControlProgram(
                name=name, int_offset=int_offset, float_offset=float_offset
            )
            # force_mode_set_gain_scaling(0.5) at start-up is a 5.0+ line of the script.
            if self.config.version[0] >= 5:
                self.program.gain_scaling = 0.5
            self.runtime_state = PLAYING
            self.stop_reason = ""
            self._write_async(-1)
            self.output_int[int_offset] = RDY_FOR_CMD
            self.log(
                f"program {name} started (register offsets int {int_offset}, float {float_offset})"
            )

    def _in_int(self, i: int) -> int:
        assert self.program is not None
        return self.input_int[self.program.int_offset + i]

    def _in_float(self, i: int) -> float:
        assert self.program is not None
        return self.input_double[self.program.float_offset + i]

    def _in_vec6(self, i: int) -> np.ndarray:
        return np.array([self._in_float(i + k) for k in range(6)])

    def _out_int(self, i: int, value: int) -> None:
        assert self.program is not None
        self.output_int[self.program.int_offset + i] = int(value)

    def _out_float(self, i: int, value: float) -> None:
        assert self.program is not None
        self.output_double[self.program.float_offset + i] = float(value)

    def _write_async(self, value: int) -> None:
        """The script's write_async_progress_register (bit layout from ur_rtde's script)."""
        p = self.program
        if p is None:
            return
        p.async_wr_count = (p.async_wr_count + 1) % 128
        if value == 0:
            p.async_op_id = (p.async_op_id + 1) % 128
        reg = p.async_wr_count * 65536 + p.async_op_id * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self._out_int(2, reg)

    def _program_cycle(self) -> None:
        """One pass of the control script's main loop (it runs once per control cycle)."""
        p = self.program
        if p is None or self.runtime_state != PLAYING:
            return
        if p.waiting == "motion":
            if self.motion is not None and not self.motion.done:
                return  # the script is inside a blocking movel/stopl
            p.waiting = None
            self.motion = None
            self._out_int(0, DONE_WITH_CMD)
            return
        cmd = self._in_int(0)
        try:
            if cmd in _REALTIME:
                self._process(cmd)
                self._out_int(0, RDY_FOR_CMD)
            elif cmd == 0:
                p.executing = False
                self._out_int(0, RDY_FOR_CMD)
            elif not p.executing:
                p.executing = True
                keep_running = self._process(cmd)
                if not keep_running:
                    self.stop_program("stopScript received")
                elif p.waiting is None and self.program is p and self.runtime_state == PLAYING:
                    self._out_int(0, DONE_WITH_CMD)
        except ScriptError as exc:
            self.stop_program(f"script error: {exc}")

    def _process(self, cmd: int) -> bool:
        """Execute one command; returns False for stopScript (the script's loop ends)."""
        p = self.program
        assert p is not None
        if cmd == 255:
            self.log("Received stop script!")
            return False
        if cmd == 3:
            pose = self._in_vec6(0)
            v, a = self._in_float(6), self._in_float(7)
            asynchronous = self._in_int(1) == 1
            self._stop_async_move()
            self._start_movel(pose, v, a, asynchronous)
            if asynchronous:
                p.async_move = True
                self._write_async(0)
            else:
                p.waiting = "motion"
        elif cmd == 6:
            self.force_mode = _ForceMode(
                frame=self._in_vec6(0),
                selection=[self._in_int(2 + k) for k in range(6)],
                wrench=self._in_vec6(6),
                limits=self._in_vec6(12),
                type=self._in_int(1),
            )
            if self.force_mode.type != 2:
                self.log(
                    f"force mode type {self.force_mode.type} simulated as type 2 (frame not transformed)"
                )
        elif cmd == 7:
            self.force_mode = None
            self._start_stop(10.0)
            p.waiting = "motion"
        elif cmd == 8:
            self.ft_offset = np.concatenate([self.external_force, np.zeros(3)])
            self.log("ftsensor zeroed")
        elif cmd == 10:
            xd = self._in_vec6(0)
            a = self._in_float(6)
            if self.motion is None or self.motion.kind != "speedl":
                self.motion = _Motion(kind="speedl", acceleration=a, target=xd)
            else:
                self.motion.target, self.motion.acceleration = xd, a
            p.speeding = True
        elif cmd == 15:
            p.speeding = False
            self._start_stop(self._in_float(0))
            p.waiting = "motion"
        elif cmd == 17:
            self.payload = (
                self._in_float(0),
                [self._in_float(1), self._in_float(2), self._in_float(3)],
            )
        elif cmd == 20:
            p.damping = self._in_float(0)
        elif cmd == 21:
            p.gain_scaling = self._in_float(0)
        elif cmd == 26:
            # get_steptime() exists from PolyScope 5.4; ur_rtde strips the call on older versions.
            if self._version_at_least(5, 4):
                self._out_float(0, self.dt)
        elif cmd == 28:
            if self._version_at_least(5, 3):
                for k in range(6):
                    self._out_float(k, float(self.target_waypoint[k]))
        elif cmd == 29:
            self.tcp_offset = self._in_vec6(0)
        elif cmd == 31:
            if self._version_at_least(3, 8):
                self.trigger_protective_stop("protective_stop() called by the program")
        elif cmd in (33, 34):
            decel = self._in_float(0)
            asynchronous = self._in_int(1) == 1
            self._stop_async_move()
            self._start_stop(decel)
            if asynchronous:
                self.motion.asynchronous = True  # type: ignore[union-attr]
                p.async_move = True
                self._write_async(0)
            else:
                p.waiting = "motion"
        elif cmd == 35:
            freq = self._in_float(0)
            variable = f"input_int_register_{p.int_offset}"
            self.watchdog = _Watchdog(variable, freq, "stop", time.monotonic())
            self.log(f"rtde watchdog on {variable} at {freq} Hz")
        elif cmd == 47:
            steady = self.force_mode is None and not np.any(np.abs(self.velocity) > 1e-9)
            self._out_int(1, 1 if steady else 0)
        else:
            raise ScriptError(f"command {cmd} is not simulated by the loopback controller")
        return True

    def _version_at_least(self, major: int, minor: int) -> bool:
        v = self.config.version
        return v[0] > major or (v[0] == major and v[1] >= minor)

    def _stop_async_move(self) -> None:
        p = self.program
        if p is not None and p.async_move:
            p.async_move = False
            self._write_async(-1)

    # ------------------------------------------------------------------ motion
    def _start_movel(self, pose: np.ndarray, v: float, a: float, asynchronous: bool) -> None:
        start = self.pose.copy()
        length = float(np.linalg.norm(self._free(pose[:3] - start[:3])))
        angle = float(np.linalg.norm(pose[3:] - start[3:]))
        self.motion = _Motion(
            kind="movel",
            velocity=max(v, 1e-6),
            acceleration=max(a, 1e-6),
            target=pose.copy(),
            start=start,
            length=length if length > 1e-9 else angle,
            speed=max(0.0, float(np.linalg.norm(self.velocity[:3]))) if length > 1e-9 else 0.0,
            asynchronous=asynchronous,
        )
        self.target_waypoint = pose.copy()

    def _start_stop(self, decel: float) -> None:
        # An injected disturbance stands for a trajectory fault of the controller, so a stop
        # command ends it (an external push would not stop, but tests need a stoppable fault).
        self._clear_disturbance()
        self.motion = _Motion(kind="stop", acceleration=max(decel, 1e-6))
        if self.program is not None:
            self.program.speeding = False

    def _free(self, vec: np.ndarray) -> np.ndarray:
        """Part of a base-frame translation along axes the force controller does not own."""
        fm = self.force_mode
        if fm is None:
            return vec
        r = rotvec_to_matrix(fm.frame[3:])
        local = r.T @ vec
        for i in range(3):
            if fm.selection[i]:
                local[i] = 0.0
        return r @ local

    def _motion_velocity(self) -> tuple[np.ndarray, np.ndarray | None]:
        """Linear velocity (3) commanded this cycle and the orientation to set (or None)."""
        m = self.motion
        dt = self.dt
        lin = self.velocity[:3].copy()
        if m is None:
            return np.zeros(3), None
        if m.kind == "speedl":
            assert m.target is not None
            lin = lin + limit_norm(m.target[:3] - lin, m.acceleration * dt)
            omega = self.velocity[3:] + limit_norm(
                m.target[3:] - self.velocity[3:], m.acceleration * dt
            )
            self.velocity[3:] = omega
            return lin, None
        if m.kind == "stop":
            step = m.acceleration * dt
            lin = limit_norm(lin, max(0.0, float(np.linalg.norm(lin)) - step))
            omega = limit_norm(
                self.velocity[3:], max(0.0, float(np.linalg.norm(self.velocity[3:])) - step)
            )
            self.velocity[3:] = omega
            if not np.any(lin) and not np.any(omega):
                self._finish_motion()
            return lin, None
        # movel: an online trapezoid along the straight line to the target.
        assert m.target is not None and m.start is not None
        self.velocity[3:] = 0.0
        remaining = m.length - m.progress
        step = m.acceleration * dt
        speed = min(m.speed + step, m.velocity, _braking_speed(remaining, m.acceleration, dt))
        if remaining <= speed * dt or m.length <= 1e-12:
            m.progress = m.length
            step_speed = remaining / dt if m.length > 1e-12 else 0.0
            m.speed = 0.0
            done = True
        else:
            m.progress += speed * dt
            m.speed = speed
            step_speed = speed
            done = False
        direction = self._free(m.target[:3] - m.start[:3])
        n = float(np.linalg.norm(direction))
        lin = direction / n * step_speed if n > 1e-12 else np.zeros(3)
        s = 1.0 if m.length <= 1e-12 else m.progress / m.length
        orientation = interpolate_rotvec(m.start[3:], m.target[3:], s)
        if done:
            # Land exactly on the free coordinates of the target (no drift from summing steps).
            free_err = self._free(m.target[:3] - self.pose[:3])
            lin = free_err / dt
            self._finish_motion()
        return lin, orientation

    def _finish_motion(self) -> None:
        m = self.motion
        if m is None:
            return
        m.done = True
        p = self.program
        if m.asynchronous and p is not None and p.async_move:
            p.async_move = False
            self._write_async(-1)
        if p is None or p.waiting != "motion":
            self.motion = None

    def _force_control(self, lin: np.ndarray) -> np.ndarray:
        """Replace the compliant components of ``lin`` by the force controller's velocity."""
        fm = self.force_mode
        if fm is None:
            return lin
        r = rotvec_to_matrix(fm.frame[3:])
        local = r.T @ lin
        applied = r.T @ (-self.external_force)  # the force the robot applies to the world
        current = r.T @ self.velocity[:3]
        gain = self.config.force_mode_admittance * (
            self.program.gain_scaling if self.program else 1.0
        )
        normal = np.asarray(getattr(self.contact, "normal", (0.0, 0.0, 1.0)), dtype=float)
        stiffness = self._local_stiffness(normal)
        if stiffness > 0:
            # A discrete admittance loop against stiffness k is stable for gain*k*dt < 2;
            # the simulated controller keeps it well damped, as a tuned real one is.
            gain = min(gain, 0.5 / (stiffness * self.dt))
        accel = self.config.force_mode_acceleration
        for i in range(3):
            if fm.selection[i]:
                error = fm.wrench[i] - applied[i]
                want = gain * error
                if stiffness > 0:
                    # Never faster than what can still be braked (at the acceleration cap)
                    # before the force error is gone: no overshoot on stiff contacts.
                    reach = _braking_speed(abs(error) / stiffness, accel, self.dt)
                    want = max(-reach, min(reach, want))
                want = max(-fm.limits[i], min(fm.limits[i], want))
                step = accel * self.dt
                local[i] = current[i] + max(-step, min(step, want - current[i]))
        return r @ local

    def _local_stiffness(self, normal: np.ndarray) -> float:
        delta = 1e-5
        probe = self.pose.copy()
        probe[:3] -= normal * delta
        return max(
            0.0,
            (float(self.contact.normal_force(probe)) - float(self.contact.normal_force(self.pose)))
            / delta,
        )

    def _update_wrench(self) -> None:
        normal = np.asarray(getattr(self.contact, "normal", (0.0, 0.0, 1.0)), dtype=float)
        fn = float(self.contact.normal_force(self.pose))
        force = fn * normal
        mu = float(getattr(self.contact, "friction", 0.0) or 0.0)
        if fn > 0 and mu > 0:
            v = self.velocity[:3]
            tangential = v - normal * float(normal @ v)
            speed = float(np.linalg.norm(tangential))
            if speed > 1e-6:
                force = force - mu * fn * tangential / speed
        self.external_force = force
        wrench = np.concatenate([force, np.zeros(3)]) - self.ft_offset
        if self.config.force_noise > 0:
            wrench[:3] += self._rng.normal(0.0, self.config.force_noise, 3)
        self.tcp_force = wrench

    # ------------------------------------------------------------------ tick
    def tick(self) -> None:
        """Advance one control cycle: watchdog, control script, motion, contact."""
        with self.lock:
            self.time += self.dt
            self._check_watchdog()
            self._program_cycle()
            if self.runtime_state == PLAYING or self.motion is not None:
                lin, orientation = self._motion_velocity()
            else:
                lin, orientation = np.zeros(3), None
            lin = self._force_control(lin) + self._disturbance()
            self.pose[:3] += lin * self.dt
            self.velocity[:3] = lin
            if orientation is not None:
                self.pose[3:] = orientation
            elif np.any(self.velocity[3:]):
                self.pose[3:] = integrate_rotvec(self.pose[3:], self.velocity[3:], self.dt)
            self._update_wrench()
            if float(np.linalg.norm(self.external_force)) > self.config.protective_force_limit:
                self.trigger_protective_stop(
                    f"TCP force {np.linalg.norm(self.external_force):.1f} N above the controller's "
                    f"{self.config.protective_force_limit:.1f} N limit"
                )
                self._update_wrench()
            if self.skin is not None:
                self._step_skin()

    def _step_skin(self) -> None:
        try:
            self.skin.step(self)
        except Exception as exc:  # a skin bug must not stop the arm's clock; say so in the log
            self._skin_errors += 1
            if self._skin_errors <= 3:
                self.log(f"simulated skin failed: {type(exc).__name__}: {exc}")

    def _disturbance(self) -> np.ndarray:
        target = self.disturbance_target if self.time < self.disturbance_until else np.zeros(3)
        step = self.disturbance_acceleration * self.dt
        delta = target - self.disturbance_velocity
        self.disturbance_velocity = self.disturbance_velocity + (
            delta if math.isinf(step) else limit_norm(delta, step)
        )
        return self.disturbance_velocity

    def _check_watchdog(self) -> None:
        wd = self.watchdog
        if wd is None or wd.min_frequency <= 0:
            return
        if time.monotonic() - wd.last_update > 1.0 / wd.min_frequency:
            message = f"RTDE input watchdog: no update of {wd.variable} for {1.0 / wd.min_frequency:.3f} s"
            if wd.action == "stop":
                self.stop_program(message)
            elif wd.action == "pause":
                self._halt()
                self.runtime_state = PAUSED
                self.log(message)
            else:
                wd.last_update = time.monotonic()
                self.log(message)

    # ------------------------------------------------------------------ dashboard
    def dashboard(self, line: str) -> str | None:
        """Answer one dashboard command (without its newline); ``None`` closes the connection."""
        cmd = line.strip()
        low = cmd.lower()
        with self.lock:
            if low == "quit":
                return None
            if low == "polyscopeversion":
                return f"URSoftware {self.config.polyscope_version} (loopback)"
            if low == "get serial number":
                return self.config.serial_number
            if low == "get robot model":
                return self.config.robot_model
            if low == "is in remote control":
                return "true"
            if low == "running":
                return f"Program running: {'true' if self.program_running else 'false'}"
            if low == "programstate":
                name = self.program.name if self.program else "<unnamed>"
                state = {PLAYING: "PLAYING", PAUSED: "PAUSED"}.get(self.runtime_state, "STOPPED")
                return f"{state} {name}"
            if low == "robotmode":
                names = {
                    ROBOT_MODE_POWER_OFF: "POWER_OFF",
                    ROBOT_MODE_IDLE: "IDLE",
                    ROBOT_MODE_RUNNING: "RUNNING",
                }
                return f"Robotmode: {names.get(self.robot_mode, 'RUNNING')}"
            if low in ("safetymode", "safetystatus"):
                mode = "PROTECTIVE_STOP" if self.protective_stopped else "NORMAL"
                return f"{'Safetymode' if low == 'safetymode' else 'Safetystatus'}: {mode}"
            if low == "stop":
                if self.runtime_state == STOPPED:
                    return "Failed to execute: stop"
                self.stop_program("dashboard stop")
                return "Stopped"
            if low == "pause":
                if self.runtime_state != PLAYING:
                    return "Failed to execute: pause"
                self._halt()
                self.runtime_state = PAUSED
                return "Pausing program"
            if low == "play":
                if (
                    self.runtime_state == PAUSED
                    and self.program is not None
                    and not self.protective_stopped
                ):
                    self.runtime_state = PLAYING
                    return "Starting program"
                return "Failed to execute: play"
            if low == "unlock protective stop":
                if self.protective_stopped:
                    elapsed = time.monotonic() - (self.protective_stop_time or 0.0)
                    if elapsed < self.config.unlock_delay:
                        return (
                            "Cannot unlock protective stop until 5s after occurrence. "
                            "Always inspect cause of protective stop before unlocking"
                        )
                    self.safety_mode = SAFETY_NORMAL
                    self.protective_stop_reason = ""
                    self.log("protective stop released")
                return "Protective stop releasing"
            if low == "power on":
                if self.robot_mode == ROBOT_MODE_POWER_OFF:
                    self.robot_mode = ROBOT_MODE_IDLE
                return "Powering on"
            if low == "power off":
                self.stop_program("power off")
                self.robot_mode = ROBOT_MODE_POWER_OFF
                return "Powering off"
            if low == "brake release":
                if self.robot_mode != ROBOT_MODE_POWER_OFF:
                    self.robot_mode = ROBOT_MODE_RUNNING
                return "Brake releasing"
            if low == "close popup":
                return "closing popup"
            if low == "close safety popup":
                return "closing safety popup"
            if low.startswith("popup "):
                return "showing popup"
            if low == "restart safety":
                self.safety_mode = SAFETY_NORMAL
                self.robot_mode = ROBOT_MODE_POWER_OFF
                return "Restarting safety"
            if low.startswith("addtolog "):
                self.log(cmd[len("addToLog ") :])
                return "Added log message"
            if low == "get loaded program":
                return "No program loaded"
            if low == "isprogramsaved":
                return "true <unnamed>"
            if low.startswith("load "):
                return f"File not found: {cmd[5:]}"
            if low == "shutdown":
                return "Shutting down"
            return f"could not understand: '{cmd}'"


def _braking_speed(distance: float, acceleration: float, dt: float) -> float:
    """Fastest speed from which braking by ``acceleration * dt`` per cycle still stops within
    ``distance`` (the discrete form of sqrt(2 a d); the continuous one brakes harder than a)."""
    step = acceleration * dt
    return step * (-0.5 + math.sqrt(0.25 + 2.0 * max(distance, 0.0) / (step * dt)))


def _injected_offset(text: str, kind: str) -> int:
    """Register offset ur_rtde injects after ``# int register offset`` / ``# float ...``."""
    m = re.search(rf"reg_offset_{kind}\s*=\s*(?:#[^\n]*\n\s*)?(\d+)", text)
    if m:
        return int(m.group(1))
    m = re.search(rf"# {kind} register offset\n\s*(\d+)", text)
    return int(m.group(1)) if m else 0
