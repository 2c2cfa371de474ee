"""A simulated UR controller: one control cycle at a time (:meth:`SimulatedController.tick`),
the TCP integrated kinematically against a pluggable contact model.

The controller composes its concerns, each in its own module: the RTDE registers
(:mod:`~aptkt.sim.loopback.registers`), ur_rtde's control script (:mod:`~aptkt.sim.loopback.
script`), motion and force control (:mod:`~aptkt.sim.loopback.motion`), the RTDE watchdog
(:mod:`~aptkt.sim.loopback.watchdog`), injected faults (:mod:`~aptkt.sim.loopback.faults`)
and the dashboard's commands (:mod:`~aptkt.sim.loopback.dashboard`). This module holds the
robot's state and its safety: protective stops, program stops, the controller's force limit.

All methods are called with :attr:`SimulatedController.lock` held by the servers; the tick
advances the simulation by one control period.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from aptkt.sim.loopback import contact as contact_models
from aptkt.sim.loopback import dashboard
from aptkt.sim.loopback.config import (
    PAUSED,
    PLAYING,
    ROBOT_MODE_RUNNING,
    SAFETY_NORMAL,
    SAFETY_PROTECTIVE_STOP,
    STOPPED,
    ControllerConfig,
)
from aptkt.sim.loopback.faults import Disturbance
from aptkt.sim.loopback.motion import (
    ForceMode,
    Motion,
    contact_wrench,
    local_stiffness,
)
from aptkt.sim.loopback.registers import RtdeRegisters, output_values
from aptkt.sim.loopback.rotvec import integrate_rotvec
from aptkt.sim.loopback.script import ControlScript, recognise
from aptkt.sim.loopback.tcp_skin import SimulatedSkin, SkinConfig
from aptkt.sim.loopback.watchdog import Watchdog

__all__ = ["SimulatedController"]


class SimulatedController:
    """One simulated UR controller. Thread-safe through :attr:`lock` (held by every caller)."""

    #: Controller time (s since "boot"); survives reset().
    time: float

    def __init__(self, config: ControllerConfig | None = None):
        self.config: ControllerConfig = config or ControllerConfig()
        self.lock = threading.RLock()
        self.dt = 1.0 / self.config.frequency
        self._rng = np.random.default_rng(self.config.seed)
        self.contact = contact_models.build(self.config.contact)
        self.text_log: deque[tuple[float, str]] = deque(maxlen=500)
        self.received_scripts: deque[str] = deque(maxlen=8)
        self.registers = RtdeRegisters()
        self.disturbance = Disturbance()
        self.skin: Any = None
        if self.config.skin is not None:
            self.skin = SimulatedSkin(SkinConfig.from_spec(self.config.skin))
        self._skin_errors = 0
        #: Linear moves commanded to a pose in contact with an object (presses), since the
        #: start: a test waits for the n-th, whatever the machine's load did to its timing.
        self.moves_into_contact = 0
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, pose: Sequence[float] | None = None, keep_program: bool = False) -> None:
        """Back to a clean state: pose, no motion, no fault. The program survives if asked."""
        with self.lock:
            self.time = 0.0 if not hasattr(self, "time") else self.time
            self.pose = np.array(pose if pose is not None else self.config.start_pose, dtype=float)
            self.velocity = np.zeros(6)
            self.motion: Motion | None = None
            self.force_mode: ForceMode | None = None
            self.ft_offset = np.zeros(6)
            self.external_force = np.zeros(3)
            self.tcp_force = np.zeros(6)
            self._target_waypoint = self.pose.copy()
            self.robot_mode: int = ROBOT_MODE_RUNNING
            self.safety_mode: int = SAFETY_NORMAL
            self.protective_stop_time: float | None = None
            self.protective_stop_reason = ""
            self.tcp_offset = np.zeros(6)
            self.disturbance.clear()
            self.payload: tuple[float, list[float]] = (0.0, [0.0, 0.0, 0.0])
            if not keep_program or getattr(self, "program", None) is None:
                self.program: ControlScript | None = None
                self.runtime_state: int = STOPPED
                self.watchdog: Watchdog | None = None
                self.output_int[0] = 0
            self.stop_reason = ""

    # The registers under the names the servers and tests read them by.
    @property
    def input_int(self) -> list[int]:
        return self.registers.input_int

    @property
    def input_double(self) -> list[float]:
        return self.registers.input_double

    @property
    def output_int(self) -> list[int]:
        return self.registers.output_int

    @property
    def output_double(self) -> list[float]:
        return self.registers.output_double

    @property
    def program_running(self) -> bool:
        return self.runtime_state == PLAYING

    @property
    def protective_stopped(self) -> bool:
        return self.safety_mode == SAFETY_PROTECTIVE_STOP

    def log(self, message: str) -> None:
        self.text_log.append((self.time, message))

    def at_least(self, major: int, minor: int) -> bool:
        return self.config.at_least(major, minor)

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
                "watchdog": None if self.watchdog is None else self.watchdog.describe(),
                "moving": bool(np.any(np.abs(self.velocity) > 1e-9)),
                "moves_into_contact": self.moves_into_contact,
                "skin": None if self.skin is None else self.skin.stats(),
                "text_log": [m for _, m in list(self.text_log)[-40:]],
            }

    def normal_force(self) -> float:
        return float(self.contact.normal_force(self.pose))

    def set_contact(self, spec: Mapping[str, Any] | None) -> None:
        with self.lock:
            self.contact = contact_models.build(spec)
            self.config.contact = None if spec is None else dict(spec)

    # ------------------------------------------------------------------ safety and faults
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
                    self.program.interrupted()

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

    def pause(self) -> None:
        """The program pauses (dashboard ``pause``, the watchdog): the arm halts."""
        self._halt()
        self.runtime_state = PAUSED

    def _halt(self) -> None:
        self.motion = None
        self.force_mode = None
        self.velocity = np.zeros(6)
        self.disturbance.clear()

    def disturb(
        self, velocity: Sequence[float], duration: float, acceleration: float | None = None
    ) -> None:
        """An external push (or a misbehaving controller): the TCP gets an extra base-frame
        velocity, reached at ``acceleration`` (None: at once), for ``duration`` seconds."""
        with self.lock:
            self.disturbance.start(velocity, duration, acceleration, self.time)
            self.log(f"disturbance {self.disturbance.target.tolist()} m/s for {duration} s")

    def _check_watchdog(self) -> None:
        wd = self.watchdog
        message = None if wd is None else wd.expired(time.monotonic())
        if wd is None or message is None:
            return
        if wd.action == "stop":
            self.stop_program(message)
        elif wd.action == "pause":
            self.pause()
            self.log(message)
        else:
            wd.last_update = time.monotonic()
            self.log(message)

    # ------------------------------------------------------------------ RTDE
    def claim_inputs(self, conn_id: int, names: Sequence[str]) -> list[str]:
        """Types for an input recipe; a variable another connection writes is ``IN_USE``."""
        with self.lock:
            return self.registers.claim(conn_id, names)

    def release_inputs(self, conn_id: int) -> None:
        with self.lock:
            self.registers.release(conn_id)

    def apply_inputs(self, values: Mapping[str, Any]) -> None:
        now = time.monotonic()
        with self.lock:
            self.registers.apply(values)
            if self.watchdog is not None and self.watchdog.variable in values:
                self.watchdog.last_update = now

    def output_values(self, names: Iterable[str]) -> list[Any]:
        with self.lock:
            return output_values(self.registers, self, names)

    # ------------------------------------------------------------------ programs
    def load_script(self, text: str, port: int) -> None:
        """A complete program arrived on a script port: it replaces the running program."""
        with self.lock:
            self.received_scripts.append(text)
            name, control = recognise(text)
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
            if not control:
                self.stop_reason = (
                    f"loopback cannot run program {name!r} (only ur_rtde's control script)"
                )
                self.log(self.stop_reason)
                return
            # force_mode_set_gain_scaling(0.5) at start-up is a 5.0+ line of the script.
            program = ControlScript(
                text, self.registers, gain_scaling=0.5 if self.config.version[0] >= 5 else 1.0
            )
            self.program = program
            self.runtime_state = PLAYING
            self.stop_reason = ""
            program.start()
            self.log(
                f"program {name} started (register offsets int {program.int_offset}, "
                f"float {program.float_offset})"
            )

    # What the control script commands (aptkt.sim.loopback.script.ScriptHost).
    def move_linear(self, pose: np.ndarray, v: float, a: float, asynchronous: bool) -> None:
        self.motion = Motion.movel(self.pose, pose, self.velocity, v, a, asynchronous, self._free)
        self._target_waypoint = pose.copy()
        if self.contact.normal_force(pose) > 0:
            self.moves_into_contact += 1

    def speed_linear(self, velocity: np.ndarray, acceleration: float) -> None:
        if self.motion is None or self.motion.kind != "speedl":
            self.motion = Motion(kind="speedl", acceleration=acceleration, target=velocity)
        else:
            self.motion.target, self.motion.acceleration = velocity, acceleration

    def stop_linear(self, deceleration: float, asynchronous: bool) -> None:
        # An injected disturbance stands for a trajectory fault of the controller, so a stop
        # command ends it (an external push would not stop, but tests need a stoppable fault).
        self.disturbance.clear()
        self.motion = Motion(kind="stop", acceleration=max(deceleration, 1e-6))
        if asynchronous:
            self.motion.asynchronous = True
        if self.program is not None:
            self.program.speeding = False

    def motion_running(self) -> bool:
        return self.motion is not None and not self.motion.done

    def end_motion(self) -> None:
        self.motion = None

    def set_force_mode(self, mode: ForceMode | None) -> None:
        self.force_mode = mode

    def zero_ft_sensor(self) -> None:
        self.ft_offset = np.concatenate([self.external_force, np.zeros(3)])
        self.log("ftsensor zeroed")

    def set_payload(self, mass: float, cog: list[float]) -> None:
        self.payload = (mass, cog)

    def set_tcp(self, offset: np.ndarray) -> None:
        self.tcp_offset = offset

    def target_waypoint(self) -> np.ndarray:
        return self._target_waypoint

    def protective_stop(self, reason: str) -> None:
        self.trigger_protective_stop(reason)

    def set_watchdog(self, variable: str, frequency: float) -> None:
        self.watchdog = Watchdog(variable, frequency, "stop", time.monotonic())

    def is_steady(self) -> bool:
        return self.force_mode is None and not np.any(np.abs(self.velocity) > 1e-9)

    # ------------------------------------------------------------------ tick
    def tick(self) -> None:
        """Advance one control cycle: watchdog, control script, motion, contact."""
        with self.lock:
            self.time += self.dt
            self._check_watchdog()
            if self.program is not None and self.runtime_state == PLAYING:
                self.program.cycle(self)
            if self.runtime_state == PLAYING or self.motion is not None:
                lin, orientation = self._motion_velocity()
            else:
                lin, orientation = np.zeros(3), None
            lin = self._force_control(lin) + self.disturbance.step(self.time, self.dt)
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

    def _free(self, vec: np.ndarray) -> np.ndarray:
        """Part of a base-frame translation along axes the force controller does not own."""
        return vec if self.force_mode is None else self.force_mode.free(vec)

    def _motion_velocity(self) -> tuple[np.ndarray, np.ndarray | None]:
        """Linear velocity (3) commanded this cycle and the orientation to set (or None)."""
        if self.motion is None:
            return np.zeros(3), None
        lin, orientation, done = self.motion.step(self.pose, self.velocity, self.dt, self._free)
        if done:
            self._finish_motion()
        return lin, orientation

    def _finish_motion(self) -> None:
        m = self.motion
        if m is None:
            return
        m.done = True
        p = self.program
        waited_for = p is not None and p.motion_finished(m.asynchronous)
        if not waited_for:
            self.motion = None

    def _force_control(self, lin: np.ndarray) -> np.ndarray:
        """Replace the compliant components of ``lin`` by the force controller's velocity."""
        fm = self.force_mode
        if fm is None:
            return lin
        gain = self.config.force_mode_admittance * (
            self.program.gain_scaling if self.program else 1.0
        )
        return fm.control(
            lin,
            -self.external_force,  # the force the robot applies to the world
            self.velocity[:3],
            gain,
            local_stiffness(self.contact, self.pose),
            self.config.force_mode_acceleration,
            self.dt,
        )

    def _update_wrench(self) -> None:
        self.external_force = contact_wrench(self.contact, self.pose, self.velocity)
        wrench = np.concatenate([self.external_force, np.zeros(3)]) - self.ft_offset
        if self.config.force_noise > 0:
            wrench[:3] += self._rng.normal(0.0, self.config.force_noise, 3)
        self.tcp_force = wrench

    def _step_skin(self) -> None:
        try:
            self.skin.step(self)
        except Exception as exc:  # a skin bug must not stop the arm's clock; say so in the log
            self._skin_errors += 1
            if self._skin_errors <= 3:
                self.log(f"simulated skin failed: {type(exc).__name__}: {exc}")

    # ------------------------------------------------------------------ dashboard
    def dashboard(self, line: str) -> str | None:
        """Answer one dashboard command (without its newline); ``None`` closes the connection."""
        with self.lock:
            return dashboard.answer(self, line)
