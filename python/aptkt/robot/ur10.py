"""The UR10 backend: exploratory movements through ur_rtde with safety enforced in code.

Every movement is sent as an asynchronous or speed command and then *supervised* from Python
at the controller's RTDE rate (125 Hz on CB3, 500 Hz on e-Series). Each cycle checks, in
this order: the link (connected, fresh robot data), protective/emergency stop, the control
program, measured TCP speed and acceleration, the TCP wrench along the surface normal, the
skin's total normal force (and its freshness), and the workspace box of the current object.
Any violation stops the arm, retracts it upwards when the arm is still under control, and
raises a typed error (:class:`~aptkt.errors.SafetyLimitError`,
:class:`~aptkt.errors.ProtectiveStopError`, :class:`~aptkt.errors.ProgramStoppedError`,
:class:`~aptkt.errors.RobotConnectionError`, or the skin's own
:class:`~aptkt.errors.SkinError`).

Why supervise instead of blocking calls: a blocking ``moveL`` cannot be interrupted by a
skin reading, and after a lost connection ur_rtde waits for its (now stale) state for up to
300 s. So once the link is found lost, this class sends nothing more to the controller; the
controller's own RTDE watchdog (armed at connect, ``1 / limits.watchdog_timeout`` Hz) stops
the program on its side. While the arm is idle a keep-alive thread feeds that watchdog;
during a movement only the supervision loop does, so a stalled loop stops the arm too.
"""

from __future__ import annotations

import atexit
import ctypes
import math
import queue
import threading
import time
from collections import deque
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import (
    AptktError,
    ConfigError,
    ProgramStoppedError,
    ProtectiveStopError,
    RobotConnectionError,
    RobotError,
    SafetyLimitError,
    SkinDisconnectedError,
)
from aptkt.robot.base import ForceReading, Placement, SafetyLimits
from aptkt.robot.workspace import DEFAULT_TOOL_ORIENTATION, WorkspaceConfig, load_workspace

__all__ = ["UR10"]

_PLAYING = 2
_RECEIVE_VARIABLES = [
    "timestamp",
    "actual_TCP_pose",
    "actual_TCP_speed",
    "actual_TCP_force",
    "robot_mode",
    "safety_mode",
    "runtime_state",
    "robot_status_bits",
    "safety_status_bits",
]
# Longest a single rtde_control call may take on a healthy link (s).
_COMMAND_TIMEOUT = 10.0
# Controller time over which the measured TCP acceleration is averaged (s).
_ACCEL_WINDOW = 0.03
# Commands ur_rtde's control script executes every cycle without a done-handshake.
_REALTIME_COMMANDS = frozenset({"speedL", "forceMode"})


class _Sample:
    __slots__ = ("host_ns", "timestamp", "pose", "speed", "force", "skin")

    def __init__(
        self,
        host_ns: int,
        timestamp: float,
        pose: np.ndarray,
        speed: np.ndarray,
        force: np.ndarray,
        skin: float,
    ):
        self.host_ns = host_ns
        self.timestamp = timestamp
        self.pose = pose
        self.speed = speed
        self.force = force
        self.skin = skin


# Clients whose last call was abandoned on a dead link. The stuck call ends on ur_rtde's own
# timeout (up to 300 s); the client must then not be destroyed wherever the last reference
# happens to drop, because its destructor sleeps 0.5 s holding the GIL: that would freeze the
# supervision of whatever moves at that moment. They are destroyed at idle moments instead
# (connect/close), or never, if still in use when the interpreter exits.
_graveyard: list[tuple[threading.Thread, Any]] = []
_graveyard_lock = threading.Lock()


def _bury(thread: threading.Thread, client: Any) -> None:
    with _graveyard_lock:
        _graveyard.append((thread, client))


def _sweep_graveyard() -> int:
    """Destroy the buried clients whose stuck call has ended; returns how many."""
    with _graveyard_lock:
        done = [entry for entry in _graveyard if not entry[0].is_alive()]
        _graveyard[:] = [entry for entry in _graveyard if entry[0].is_alive()]
    count = len(done)
    del done  # the destructors run here, at a moment chosen by the caller
    return count


@atexit.register
def _leak_clients_in_use() -> None:
    # A client still inside a stuck call must outlive the interpreter's clean-up: destroying
    # it under the running call would be a use-after-free.
    _sweep_graveyard()
    with _graveyard_lock:
        if _graveyard:
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(_graveyard))


class _Worker:
    """The one thread that calls ``rtde_control``, so a call stuck on a dead link can be
    abandoned: ur_rtde waits up to 300 s for a "done" that a stale state never shows."""

    def __init__(self, name: str):
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.thread.start()

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future[Any]:
        future: Future[Any] = Future()
        self._queue.put((future, fn, args))
        return future

    def close(self) -> None:
        self._queue.put(None)

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            future, fn, args = item
            del item
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(fn(*args))
                except BaseException as exc:  # handed to the caller through the future
                    future.set_exception(exc)
            # Drop the bound method at once: a frame of this loop must not keep the client alive.
            del future, fn, args


class UR10:
    """A UR10 (CB3 or e-Series controller) carrying the skin; implements :class:`~aptkt.robot.Robot`.

    Parameters
    ----------
    host:
        Controller address. ``connect=False`` defers the connection to :meth:`connect`.
    placements:
        Objects of the cell by name (see :mod:`aptkt.robot.workspace`); only used to look up
        placements by name, every movement gets its :class:`Placement` explicitly.
    limits:
        Safety limits enforced on every command and every supervision cycle.
    workspace:
        Optional ``(min, max)`` box every movement must stay in, also between objects.
    tool_orientation:
        TCP rotation vector used for all movements (default: skin facing straight down).
    clock:
        Nanosecond clock shared with the skin source, so both timestamp on one time base.
    retract_height:
        How far (m) to retract upwards after a fault while the arm is still controllable.
    measured_tolerance:
        Factor on ``max_speed`` / ``max_acceleration`` above which a *measured* value is a
        fault (commands are always kept within the limits themselves); measurement noise and
        the controller's own trajectory generation need some headroom.
    force_tolerance / force_tolerance_abs / settle_samples / establish_timeout:
        A slide starts once the skin force stayed within ``max(force_tolerance * F,
        force_tolerance_abs)`` of the target F for ``settle_samples`` consecutive cycles;
        ``establish_timeout`` s at most.
    """

    def __init__(
        self,
        host: str,
        placements: Mapping[str, Placement] | Iterable[Placement] = (),
        limits: SafetyLimits | None = None,
        *,
        workspace: tuple[Sequence[float], Sequence[float]] | None = None,
        tool_orientation: Sequence[float] = DEFAULT_TOOL_ORIENTATION,
        clock: Callable[[], int] = time.monotonic_ns,
        frequency: float | None = None,
        transfer_speed: float = 0.05,
        retract_height: float = 0.01,
        measured_tolerance: float = 1.5,
        force_tolerance: float = 0.15,
        force_tolerance_abs: float = 0.02,
        settle_samples: int = 5,
        establish_timeout: float = 3.0,
        trace_seconds: float = 120.0,
        max_supervision_hz: float = 250.0,
        connect: bool = True,
    ):
        self.host = host
        self.limits = limits or SafetyLimits()
        if isinstance(placements, Mapping):
            self.placements = dict(placements)
        else:
            self.placements = {p.object_name: p for p in placements}
        self.workspace = None
        if workspace is not None:
            self.workspace = (tuple(map(float, workspace[0])), tuple(map(float, workspace[1])))
        self.tool_orientation = tuple(float(v) for v in tool_orientation)
        if len(self.tool_orientation) != 3:
            raise ValueError("tool_orientation must be a rotation vector of 3 numbers")
        self._clock = clock
        self._requested_frequency = frequency
        self.frequency = frequency or 125.0
        self.transfer_speed = min(transfer_speed, self.limits.max_speed)
        self.retract_height = retract_height
        self.measured_tolerance = measured_tolerance
        self.force_tolerance = force_tolerance
        self.force_tolerance_abs = force_tolerance_abs
        self.settle_samples = settle_samples
        self.establish_timeout = establish_timeout
        self.max_supervision_hz = max_supervision_hz
        self._retracting = False
        self._trace: deque[_Sample] = deque(maxlen=max(100, int(trace_seconds * 500)))
        self._worker: _Worker | None = None
        self._control: Any = None
        self._receive: Any = None
        self._lost: str | None = None
        self._active: Placement | None = None
        self._contact_z: float | None = None
        self._skin: ForceReading | None = None
        self._mode: str | None = None  # "speed" | "force+speed" | "force" | "move"
        self._hold: tuple[str, tuple[Any, ...]] | None = None
        #: ``(start_ns, stop_ns)`` of the last hold (press) or constant-speed part of a slide,
        #: on :meth:`now_ns`'s clock; :func:`aptkt.actions.executor.explore` crops recordings to it.
        self.action_window_ns: tuple[int, int] | None = None
        self._in_motion = False
        self._keepalive: threading.Thread | None = None
        self._keepalive_stop = threading.Event()
        self._reset_supervision()
        if connect:
            self.connect()

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_config(
        cls, config: WorkspaceConfig | str | Path, host: str | None = None, **kwargs: Any
    ) -> UR10:
        """A UR10 for a workspace file (or parsed config); ``host`` overrides ``[robot] host``.

        This is what ``aptkt collect/learn --robot ur10`` build on.
        """
        if not isinstance(config, WorkspaceConfig):
            config = load_workspace(config)
        host = host or config.host
        if not host:
            raise ConfigError(
                f"{config.source}: no robot host given (set [robot] host or pass --host)"
            )
        return cls(
            host,
            config.placements,
            config.limits,
            workspace=config.workspace,
            tool_orientation=config.tool_orientation,
            **kwargs,
        )

    def connect(self) -> None:
        """Connect, upload ur_rtde's control script and arm the controller's RTDE watchdog."""
        try:
            import rtde_control
            import rtde_receive
        except ImportError:
            raise RobotConnectionError(
                "the UR10 backend needs the ur_rtde package: pip install 'aptkt[ur10]'"
            ) from None
        self.close()
        freq = -1.0 if self._requested_frequency is None else float(self._requested_frequency)
        try:
            self._receive = rtde_receive.RTDEReceiveInterface(self.host, freq, _RECEIVE_VARIABLES)
            self._control = rtde_control.RTDEControlInterface(self.host, freq)
        except RuntimeError as exc:
            self._drop_clients()
            raise RobotConnectionError(
                f"cannot connect to the UR controller at {self.host}: {exc}"
            ) from None
        self._lost = None
        self._worker = _Worker(f"ur10-rtde-control-{self.host}")
        self.frequency = self._detect_frequency()
        self._reset_supervision()
        self._command("setWatchdog", 1.0 / self.limits.watchdog_timeout)
        self._keepalive_stop.clear()
        self._keepalive = threading.Thread(
            target=self._keep_alive, name=f"ur10-keepalive-{self.host}", daemon=True
        )
        self._keepalive.start()

    def _detect_frequency(self) -> float:
        """The controller's RTDE rate, from the spacing of its own timestamps (8 ms or 2 ms)."""
        if self._requested_frequency:
            return float(self._requested_frequency)
        stamps: list[float] = []
        deadline = time.monotonic() + 1.0
        while len(stamps) < 4 and time.monotonic() < deadline:
            ts = float(self._receive.getTimestamp())
            if not stamps or ts != stamps[-1]:
                stamps.append(ts)
            time.sleep(0.0005)
        steps = [b - a for a, b in zip(stamps, stamps[1:]) if b > a]
        if not steps:
            raise self._lose("the controller sends no data")
        return 500.0 if min(steps) < 0.005 else 125.0

    def close(self) -> None:
        """Stop the arm, end the control script and disconnect. Safe to call repeatedly."""
        self._keepalive_stop.set()
        if self._keepalive is not None:
            self._keepalive.join(timeout=2.0)
            self._keepalive = None
        if self._control is not None and self._lost is None:
            self.stop()
            try:
                if self._link_ok():
                    self._call("stopScript")
            except AptktError:
                pass
        if self._worker is not None:
            self._worker.close()
            # A call still spinning inside ur_rtde (it holds the client) would keep the old
            # connection and its input registers alive: let it end (ur_rtde gives up after
            # at most 4 s on a live link). An abandoned worker is not waited for.
            self._worker.thread.join(timeout=_COMMAND_TIMEOUT)
            self._worker = None
        self._drop_clients()
        _sweep_graveyard()

    def _drop_clients(self) -> None:
        # ur_rtde's destructors disconnect and sleep 0.5 s each *with the GIL held*; an
        # explicit disconnect() first would only add another 0.5 s per client. They must run
        # here: a client kept alive elsewhere (say, by a local variable of a frame in some
        # exception's traceback) is destroyed later by the garbage collector, and that 0.5 s
        # GIL stall inside another connection's supervision loop lets the controller's
        # watchdog stop the arm. Hence no method keeps a client in a local variable.
        self._control = self._receive = None

    def __enter__(self) -> UR10:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def connected(self) -> bool:
        return self._control is not None and self._lost is None

    def now_ns(self) -> int:
        return int(self._clock())

    def placement(self, name: str) -> Placement:
        try:
            return self.placements[name]
        except KeyError:
            raise RobotError(
                f"no placement for object {name!r} (known: {sorted(self.placements)})"
            ) from None

    # ------------------------------------------------------------------ Robot protocol
    def move_above(self, placement: Placement, clearance: float) -> None:
        _positive(clearance, "clearance")
        target = np.array(
            [placement.x, placement.y, placement.surface_z + clearance, *self.tool_orientation]
        )
        if not placement.contains(tuple(target[:3])):
            raise SafetyLimitError(
                f"{clearance * 1000:.1f} mm above {placement.object_name!r} is outside its workspace box"
            )
        self._check_global(target[:3], f"the point above {placement.object_name!r}")
        with self._motion("move_above"):
            self._active = None
            self._contact_z = None
            self._skin = None
            pose = self._peek_pose()
            if pose[2] < target[2] - 1e-4:
                # Leave the current object vertically before travelling sideways.
                up = np.array([*pose[:3], *self.tool_orientation])
                up[2] = target[2]
                self._move_to(up, self.transfer_speed)
            self._move_to(target, self.transfer_speed)
            self._active = placement

    def approach_contact(self, total_force: ForceReading, threshold: float) -> float:
        placement = self._require_active("approach_contact")
        _positive(threshold, "threshold")
        if threshold >= self.limits.max_normal_force:
            raise SafetyLimitError(
                f"contact threshold {threshold} N is not below max_normal_force {self.limits.max_normal_force} N"
            )
        with self._motion("approach_contact"):
            self._skin = total_force
            self._command("zeroFtSensor")  # wrench limits count from the contact-free reading
            self._reset_supervision()
            start = self._sample()
            if start.skin > threshold:
                self._contact_z = float(start.pose[2])
                return self._contact_z
            # Stop short of the box floor: the stopping distance is v^2 / 2a (25 um by default).
            floor = placement.workspace_min[2] + 0.0005
            bottom = max(start.pose[2] - self.limits.max_approach_travel, floor)
            self._mode = "speed"
            self._command(
                "speedL",
                [0.0, 0.0, -self.limits.approach_speed, 0.0, 0.0, 0.0],
                self.limits.max_acceleration,
                0.0,
            )

            def reached(s: _Sample) -> bool:
                if s.skin > threshold:
                    return True
                if s.pose[2] <= bottom:
                    raise SafetyLimitError(
                        f"no contact with {placement.object_name!r} after "
                        f"{(start.pose[2] - s.pose[2]) * 1000:.1f} mm (skin {s.skin:.3f} N <= {threshold} N); "
                        f"stopped at the {'workspace floor' if bottom == floor else 'approach travel limit'}"
                    )
                return False

            travel = start.pose[2] - bottom
            contact = self._supervise(
                until=reached,
                timeout=travel / self.limits.approach_speed + 2.0,
                what="the approach",
            )
            self._command("speedStop", self.limits.max_acceleration)
            self._mode = None
            self._contact_z = float(contact.pose[2])
            return self._contact_z

    def press(self, depth: float, hold_time: float) -> None:
        self._require_contact("press")
        _positive(depth, "depth")
        _non_negative(hold_time, "hold_time")
        if depth > self.limits.max_depth:
            raise SafetyLimitError(
                f"press depth {depth * 1000:.2f} mm exceeds max_depth {self.limits.max_depth * 1000:.2f} mm"
            )
        assert self._contact_z is not None
        target = np.array([*self._peek_pose()[:3], *self.tool_orientation])
        target[2] = self._contact_z - depth
        self._check_box(target[:3], "the press depth")
        with self._motion("press"):
            self._move_to(target, self.limits.approach_speed)
            start = self.now_ns()
            self._supervise(duration=hold_time, what="the hold")
            self.action_window_ns = (start, self.now_ns())

    def slide(
        self,
        normal_force: float,
        speed: float,
        duration: float,
        direction: tuple[float, float],
        total_force: ForceReading,
    ) -> None:
        self._require_contact("slide")
        _positive(normal_force, "normal_force")
        _positive(speed, "speed")
        _positive(duration, "duration")
        if normal_force > self.limits.max_normal_force:
            raise SafetyLimitError(
                f"slide force {normal_force} N exceeds max_normal_force {self.limits.max_normal_force} N"
            )
        if speed > self.limits.max_speed:
            raise SafetyLimitError(
                f"slide speed {speed} m/s exceeds max_speed {self.limits.max_speed} m/s"
            )
        dx, dy = float(direction[0]), float(direction[1])
        norm = math.hypot(dx, dy)
        if not norm > 1e-9:
            raise ValueError("slide direction must not be zero")
        dx, dy = dx / norm, dy / norm
        pose = self._peek_pose()
        # Ramp up, `duration` at full speed, ramp down: all of it must stay in the box.
        ramp = speed / self.limits.max_acceleration
        reach = speed * duration + speed * ramp
        self._check_box(
            np.array([pose[0] + dx * reach, pose[1] + dy * reach, pose[2]]),
            f"a {reach * 1000:.1f} mm slide",
        )
        with self._motion("slide"):
            self._skin = total_force
            self._reset_supervision()
            self._mode = "force"
            # Compliant along base z only, pushing down with the target force (the wrench is
            # what the arm applies to the object); z speed capped at twice the approach speed.
            self._command(
                "forceMode",
                [0.0] * 6,
                [0, 0, 1, 0, 0, 0],
                [0.0, 0.0, -normal_force, 0.0, 0.0, 0.0],
                2,
                [0.005, 0.005, 2.0 * self.limits.approach_speed, 0.1, 0.1, 0.1],
            )
            settled = [0]

            def established(s: _Sample) -> bool:
                band = max(self.force_tolerance * normal_force, self.force_tolerance_abs)
                ok = abs(s.skin - normal_force) <= band
                settled[0] = settled[0] + 1 if ok else 0
                return settled[0] >= self.settle_samples

            self._supervise(
                until=established,
                timeout=self.establish_timeout,
                what=f"establishing {normal_force} N",
            )
            self._mode = "force+speed"
            self._command(
                "speedL",
                [dx * speed, dy * speed, 0.0, 0.0, 0.0, 0.0],
                self.limits.max_acceleration,
                0.0,
            )
            # The controller takes the command at its next cycle and ramps at max_acceleration:
            # full speed one period + `ramp` s after sending (the planned window; the trace in
            # recording_metadata shows the measured speed).
            start = self.now_ns() + int(round((ramp + 1.0 / self.frequency) * 1e9))
            self._supervise(duration=ramp + duration, what="the slide")
            self.action_window_ns = (start, start + int(round(duration * 1e9)))
            self._leave_force_mode()

    def lift(self, height: float) -> None:
        _positive(height, "height")
        with self._motion("lift"):
            self._leave_force_mode()
            self._lift_by(height)
            self._contact_z = None
            self._skin = None

    def wait(self, seconds: float) -> None:
        _non_negative(seconds, "seconds")
        with self._motion("wait"):
            self._supervise(duration=seconds, what="the wait")

    def stop(self) -> None:
        """Stop every motion now. Never raises; sends nothing once the link is lost."""
        if self._control is None or self._lost is not None:
            return
        decel = self.limits.max_acceleration * 4.0
        # ur_rtde's script kills the speed/force threads in speedStop/forceModeStop, so only
        # stop the modes that are on; stopL ends an asynchronous moveL.
        steps = []
        if self._mode in ("speed", "force+speed"):
            steps.append(("speedStop", (decel,)))
        if self._mode in ("force", "force+speed"):
            steps.append(("forceModeStop", ()))
        steps.append(("stopL", (decel,)))
        self._hold = None
        for name, args in steps:
            try:
                if not self._link_ok():
                    break
                self._call(name, *args)
            except AptktError:
                break
        self._mode = None

    def recover(self) -> None:
        """After a protective stop, a stopped program or a lost link: make the arm usable again.

        Unlocks a protective stop through the dashboard server (a real controller accepts
        that 5 s after the stop at the earliest), then reconnects and re-uploads the
        control script. Inspect the cause of the fault first.
        """
        if self._receive is not None and self._lost is None:
            try:
                stopped = bool(self._receive.isProtectiveStopped())
            except RuntimeError:
                stopped = False
            if stopped:
                import dashboard_client

                db = dashboard_client.DashboardClient(self.host)
                try:
                    db.connect()
                    db.unlockProtectiveStop()
                except RuntimeError as exc:
                    raise ProtectiveStopError(f"cannot unlock the protective stop: {exc}") from None
                finally:
                    db.disconnect()
        self._active = None
        self._contact_z = None
        self._skin = None
        self.connect()

    # ------------------------------------------------------------------ recording metadata
    def trace(
        self, start_ns: int | None = None, stop_ns: int | None = None
    ) -> dict[str, np.ndarray]:
        """Robot samples seen by the supervision loop in ``[start_ns, stop_ns)`` (host clock).

        ``robot_timestamp`` is the controller's own clock (s since boot), so the skin's
        host timestamps and the robot's can be related sample by sample.
        """
        samples = [
            s
            for s in list(self._trace)
            if (start_ns is None or s.host_ns >= start_ns)
            and (stop_ns is None or s.host_ns < stop_ns)
        ]
        return {
            "host_t_ns": np.array([s.host_ns for s in samples], dtype=np.int64),
            "robot_timestamp": np.array([s.timestamp for s in samples], dtype=np.float64),
            "tcp_pose": np.array([s.pose for s in samples], dtype=np.float64).reshape(-1, 6),
            "tcp_speed": np.array([s.speed for s in samples], dtype=np.float64).reshape(-1, 6),
            "tcp_force": np.array([s.force for s in samples], dtype=np.float64).reshape(-1, 6),
            "skin_force": np.array([s.skin for s in samples], dtype=np.float64),
        }

    def recording_metadata(self, start_ns: int, stop_ns: int) -> dict[str, Any]:
        """Metadata for a skin :class:`~aptkt.skin.Recording` of ``[start_ns, stop_ns)``: the
        robot trace (JSON-able lists) and the median host-minus-controller clock offset."""
        tr = self.trace(start_ns, stop_ns)
        offset = None
        if len(tr["host_t_ns"]):
            offset = int(
                np.median(tr["host_t_ns"] - np.round(tr["robot_timestamp"] * 1e9).astype(np.int64))
            )
        return {
            "robot": "UR10",
            "robot_host": self.host,
            "robot_frequency_hz": self.frequency,
            "robot_clock_offset_ns": offset,
            "robot_trace": {k: v.tolist() for k, v in tr.items()},
        }

    # ------------------------------------------------------------------ supervision
    def _reset_supervision(self) -> None:
        self._last_ts: float | None = None
        self._last_fresh = time.monotonic()
        self._speeds: deque[tuple[float, np.ndarray]] = deque(maxlen=64)
        self._normals: deque[float] = deque(maxlen=3)
        self._last: _Sample | None = None

    def _motion(self, what: str) -> _MotionGuard:
        return _MotionGuard(self, what)

    def _require_link(self) -> None:
        if self._control is None:
            raise RobotConnectionError(f"not connected to the UR controller at {self.host}")
        if self._lost is not None:
            raise RobotConnectionError(
                f"the link to {self.host} was lost ({self._lost}); call recover()"
            )

    def _link_ok(self) -> bool:
        """Whether it is safe to send a command: one sent on a dead link blocks for minutes."""
        try:
            if not (self._control.isConnected() and self._receive.isConnected()):
                return False
            ts = float(self._receive.getTimestamp())
        except RuntimeError:
            return False
        now = time.monotonic()
        if ts != self._last_ts:
            self._last_ts, self._last_fresh = ts, now
            return True
        return now - self._last_fresh <= self.limits.watchdog_timeout

    def _lose(self, why: str) -> RobotConnectionError:
        self._lost = why
        self._mode = None
        self._hold = None
        return RobotConnectionError(
            f"lost the link to the UR controller at {self.host}: {why}. No further commands are sent; "
            f"the controller's RTDE watchdog stops the program within {self.limits.watchdog_timeout} s"
        )

    def _command(self, name: str, *args: Any) -> Any:
        # A real-time command (speedL, forceMode) is only a value in the command register: the
        # next data package would overwrite it before the control script's next cycle reads
        # it. So it is repeated every supervision cycle instead of the watchdog kick.
        self._hold = (name, args) if name in _REALTIME_COMMANDS else None
        self._require_link()
        if not self._link_ok():
            raise self._lose(f"no fresh robot data before sending {name}")
        result = self._call(name, *args)
        if result is False:
            self._explain(name)
        return result

    def _call(self, name: str, *args: Any) -> Any:
        """Run one rtde_control method on the worker thread while watching the link.

        ur_rtde blocks on its own (possibly stale) state: a refused command returns within
        milliseconds, but one sent as the link died may wait up to 300 s, and one racing a
        program stop spins up to 4 s. So: give up at once when the link goes stale, and look
        at the controller state after a short grace period.
        """
        worker = self._worker
        if worker is None or self._control is None:
            raise RobotConnectionError(f"not connected to the UR controller at {self.host}")
        future = worker.submit(getattr(self._control, name), *args)
        start = time.monotonic()
        while True:
            try:
                return future.result(timeout=0.01)
            except FutureTimeout:
                pass
            except RuntimeError as exc:
                raise self._lose(f"{name} failed: {exc}") from None
            waited = time.monotonic() - start
            if not self._link_ok():
                self._abandon_worker()
                raise self._lose(f"{name} was sent on a link without fresh data")
            if waited > 0.2:
                try:
                    if self._receive.isProtectiveStopped() or self._receive.isEmergencyStopped():
                        raise ProtectiveStopError(
                            f"the controller is in a protective/emergency stop ({name})"
                        )
                    if self._receive.getRuntimeState() != _PLAYING:
                        raise ProgramStoppedError(
                            f"the control program is not running on the controller ({name})"
                        )
                except RuntimeError as exc:
                    raise self._lose(str(exc)) from None
            if waited > _COMMAND_TIMEOUT:
                self._abandon_worker()
                raise self._lose(f"{name} did not complete within {_COMMAND_TIMEOUT:.0f} s")

    def _abandon_worker(self) -> None:
        # The stuck call ends on ur_rtde's own timeout; its thread then exits. Nothing else
        # is queued behind it: a lost link sends nothing more.
        if self._worker is not None:
            self._worker.close()
            _bury(self._worker.thread, self._control)
            self._worker = None

    def _explain(self, name: str) -> None:
        """A command was refused: say why as precisely as the controller lets us.

        The control and receive interfaces have separate RTDE streams, so the receive side
        may show the cause one or two packages after the control side refused: look for a
        few control periods before giving up.
        """
        deadline = time.monotonic() + 5.0 / self.frequency + 0.02
        stopped = False
        first_ts: float | None = None
        while True:
            try:
                if not (self._control.isConnected() and self._receive.isConnected()):
                    raise self._lose(f"the RTDE connection closed ({name} refused)")
                ts = float(self._receive.getTimestamp())
                first_ts = ts if first_ts is None else first_ts
                if self._receive.isProtectiveStopped() or self._receive.isEmergencyStopped():
                    raise ProtectiveStopError(
                        f"the controller is in a protective/emergency stop ({name} refused)"
                    )
                # A protective stop pauses the program too: only call it a stopped program if
                # no protective stop shows up within the grace period.
                stopped = (
                    self._receive.getRuntimeState() != _PLAYING
                    or not self._control.isProgramRunning()
                )
            except RuntimeError as exc:
                raise self._lose(str(exc)) from None
            if time.monotonic() > deadline:
                if ts == first_ts:
                    raise self._lose(f"no fresh robot data after {name} was refused")
                if stopped:
                    raise ProgramStoppedError(
                        f"the control program is not running on the controller ({name} refused)"
                    )
                raise RobotError(f"the controller refused {name}")
            time.sleep(0.002)

    def _peek_pose(self) -> np.ndarray:
        """The TCP pose for planning, without limit checks (nothing moves yet)."""
        self._require_link()
        if not self._link_ok():
            raise self._lose("no fresh robot data")
        try:
            return np.asarray(self._receive.getActualTCPPose(), dtype=float)
        except RuntimeError as exc:
            raise self._lose(str(exc)) from None

    def _sample(self) -> _Sample:
        """Read robot and skin once and check every limit. Raises on any violation."""
        host_ns = self.now_ns()
        now = time.monotonic()
        try:
            if not (self._receive.isConnected() and self._control.isConnected()):
                raise self._lose("the RTDE connection closed")
            ts = float(self._receive.getTimestamp())
            fresh = ts != self._last_ts
            if fresh:
                self._last_ts, self._last_fresh = ts, now
            elif now - self._last_fresh > self.limits.watchdog_timeout:
                raise self._lose(
                    f"no fresh robot data for {now - self._last_fresh:.2f} s (watchdog)"
                )
            if self._receive.isProtectiveStopped() or self._receive.isEmergencyStopped():
                raise ProtectiveStopError(
                    "the controller entered a protective stop; the arm is stopped"
                )
            if self._receive.getRuntimeState() != _PLAYING:
                raise ProgramStoppedError(
                    "the control program on the controller stopped; the arm is stopped"
                )
            pose = np.asarray(self._receive.getActualTCPPose(), dtype=float)
            speed = np.asarray(self._receive.getActualTCPSpeed(), dtype=float)
            force = np.asarray(self._receive.getActualTCPForce(), dtype=float)
        except RuntimeError as exc:
            raise self._lose(str(exc)) from None
        skin = 0.0 if self._retracting else self._read_skin(host_ns)
        sample = _Sample(host_ns, ts, pose, speed, force, skin)
        self._last = sample
        self._trace.append(sample)
        lim = self.limits
        v = float(np.linalg.norm(speed[:3]))
        if v > lim.max_speed * self.measured_tolerance:
            raise SafetyLimitError(
                f"measured TCP speed {v:.3f} m/s exceeds the limit {lim.max_speed} m/s"
            )
        if fresh:
            self._speeds.append((ts, speed[:3].copy()))
            # Acceleration over at least ACCEL_WINDOW s of controller time: over a single
            # period the last step of any discrete trajectory looks like a spike.
            t0, v0 = self._speeds[0]
            for t_old, v_old in reversed(self._speeds):
                if ts - t_old >= _ACCEL_WINDOW:
                    t0, v0 = t_old, v_old
                    break
            if ts > t0:
                a = float(np.linalg.norm(speed[:3] - v0)) / (ts - t0)
                if a > lim.max_acceleration * self.measured_tolerance:
                    raise SafetyLimitError(
                        f"measured TCP acceleration {a:.2f} m/s^2 exceeds the limit {lim.max_acceleration} m/s^2"
                    )
            self._normals.append(abs(float(force[2])))
        if self._retracting:
            return sample  # moving up and away: force and box limits must not block the retreat
        if len(self._normals) == self._normals.maxlen:
            fn = float(np.median(self._normals))
            if fn > lim.max_normal_force:
                raise SafetyLimitError(
                    f"TCP wrench along the normal {fn:.2f} N exceeds max_normal_force {lim.max_normal_force} N"
                )
        if skin > lim.max_normal_force:
            raise SafetyLimitError(
                f"skin normal force {skin:.3f} N exceeds max_normal_force {lim.max_normal_force} N"
            )
        if self._active is not None and not self._active.contains(tuple(pose[:3])):
            raise SafetyLimitError(
                f"TCP at ({pose[0]:.4f}, {pose[1]:.4f}, {pose[2]:.4f}) left the workspace box of "
                f"{self._active.object_name!r}"
            )
        self._check_global(pose[:3], "the TCP")
        return sample

    def _read_skin(self, host_ns: int) -> float:
        skin = self._skin
        if skin is None:
            return 0.0
        value = float(skin())  # a skin source raises its own SkinError when its link fails
        if not math.isfinite(value):
            raise SafetyLimitError(f"the skin reported a non-finite normal force ({value})")
        last = getattr(skin, "last_update_ns", None)
        if callable(last):
            age = (host_ns - int(last())) * 1e-9
            if age > self.limits.watchdog_timeout:
                raise SkinDisconnectedError(
                    f"no fresh skin data for {age:.2f} s (watchdog {self.limits.watchdog_timeout} s)"
                )
        return value

    def _supervise(
        self,
        *,
        until: Callable[[_Sample], bool] | None = None,
        duration: float | None = None,
        timeout: float | None = None,
        what: str,
    ) -> _Sample:
        """Supervision cycles at the RTDE rate until ``until(sample)`` or ``duration`` s."""
        period = 1.0 / min(self.frequency, self.max_supervision_hz)
        start = time.monotonic()
        next_t = start
        while True:
            sample = self._sample()
            elapsed = time.monotonic() - start
            if until is not None and until(sample):
                return sample
            if duration is not None and elapsed >= duration:
                return sample
            if timeout is not None and elapsed >= timeout:
                raise RobotError(f"{what} did not finish within {timeout:.1f} s")
            self._kick()
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_t = time.monotonic()

    def _kick(self) -> None:
        """Feed the controller's watchdog: repeat the held real-time command, or kick."""
        name, args = self._hold or ("kickWatchdog", ())
        if self._call(name, *args) is False:
            self._explain(name)

    def _keep_alive(self) -> None:
        # Feeds the controller's watchdog while no movement is supervised. During movements the
        # supervision loop feeds it, so a stalled loop lets the controller stop the arm.
        interval = self.limits.watchdog_timeout / 5.0
        while not self._keepalive_stop.wait(interval):
            worker = self._worker
            if self._in_motion or self._lost is not None or worker is None:
                continue
            try:
                if self._receive.getRuntimeState() != _PLAYING:
                    continue
                # Through the worker, so it never interleaves with a command; never waits
                # long: a stuck worker is the supervision's business.
                worker.submit(self._control.kickWatchdog).result(timeout=interval)
            except (
                RuntimeError,
                AttributeError,
                FutureTimeout,
            ):  # AttributeError: closed meanwhile
                pass

    def _move_to(self, target: np.ndarray, speed: float) -> None:
        """Asynchronous moveL to ``target``, supervised until the controller reports it done."""
        speed = min(speed, self.limits.max_speed)
        self._check_global(target[:3], "the move target")
        start = self._sample()
        before = self._async_status()
        self._mode = "move"
        self._command(
            "moveL", [float(v) for v in target], speed, self.limits.max_acceleration, True
        )
        distance = float(np.linalg.norm(target[:3] - start.pose[:3]))
        timeout = 2.0 * (distance / speed + speed / self.limits.max_acceleration) + 1.0

        def finished(s: _Sample) -> bool:
            status = self._async_status()
            # Done = the controller ran a new asynchronous operation and it is over.
            return status[0] != before[0] and not status[1]

        done = self._supervise(until=finished, timeout=timeout, what="the moveL")
        # The receive stream may trail the control stream by a package: read on until it
        # shows a cycle after the one that reported the move done, so the pose is final.
        end = self._supervise(
            until=lambda s: s.timestamp > done.timestamp, timeout=1.0, what="the moveL"
        )
        self._mode = None
        miss = float(np.linalg.norm(end.pose[:3] - target[:3]))
        if miss > 2e-4:
            raise RobotError(f"the moveL ended {miss * 1000:.2f} mm from its target")

    def _async_status(self) -> tuple[int, bool]:
        try:
            status = self._control.getAsyncOperationProgressEx()
            return int(status.operationId()), bool(status.isAsyncOperationRunning())
        except RuntimeError as exc:
            raise self._lose(str(exc)) from None

    def _leave_force_mode(self) -> None:
        mode = self._mode
        if mode in ("speed", "force+speed"):
            self._command("speedStop", self.limits.max_acceleration)
            self._mode = "force" if mode == "force+speed" else None
        if self._mode == "force":
            self._command("forceModeStop")
        self._mode = None

    def _lift_by(self, height: float) -> None:
        pose = self._peek_pose()
        top = math.inf
        if self._active is not None:
            top = min(top, self._active.workspace_max[2])
        if self.workspace is not None:
            top = min(top, self.workspace[1][2])
        target = np.array([*pose[:3], *self.tool_orientation])
        target[2] = min(pose[2] + height, top - 1e-6)
        if target[2] > pose[2] + 1e-6:
            self._move_to(target, self.transfer_speed)

    def _check_box(self, point: np.ndarray, what: str) -> None:
        placement = self._active
        if placement is not None and not placement.contains(tuple(point)):
            raise SafetyLimitError(
                f"{what} would leave the workspace box of {placement.object_name!r}"
            )
        self._check_global(point, what)

    def _check_global(self, point: Sequence[float], what: str) -> None:
        if self.workspace is not None:
            lo, hi = self.workspace
            if not all(a <= p <= b for a, p, b in zip(lo, point, hi)):
                raise SafetyLimitError(f"{what} is outside the robot workspace box")

    def _require_active(self, what: str) -> Placement:
        self._require_link()
        if self._active is None:
            raise RobotError(f"{what} needs move_above(placement, ...) first")
        return self._active

    def _require_contact(self, what: str) -> None:
        self._require_active(what)
        if self._contact_z is None:
            raise RobotError(f"{what} needs approach_contact(...) first")

    def _fail(self, exc: BaseException) -> None:
        """Bring the arm to rest after a fault inside a movement; retract while still in control."""
        if self._lost is not None or isinstance(exc, (ProtectiveStopError, ProgramStoppedError)):
            self._mode = None  # the controller already stopped the arm, or we cannot reach it
            return
        self.stop()
        if not isinstance(exc, AptktError) or self._lost is not None:
            return  # e.g. KeyboardInterrupt or a bug: stopped, but do not move on our own
        self._retracting = True
        try:
            self._reset_supervision()
            self._lift_by(self.retract_height)
            self._contact_z = None
        except AptktError as retract_exc:
            _note(exc, f"retracting after the fault failed too: {retract_exc}")
            self.stop()
        finally:
            self._retracting = False


class _MotionGuard:
    """Marks a supervised movement; a fault inside it stops the arm, retracts and re-raises."""

    def __init__(self, robot: UR10, what: str):
        self.robot = robot
        self.what = what

    def __enter__(self) -> None:
        self.robot._require_link()
        self.robot._in_motion = True

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        try:
            if exc is not None:
                self.robot._fail(exc)
        finally:
            self.robot._in_motion = False


def _note(exc: BaseException, text: str) -> None:
    if hasattr(exc, "add_note"):
        exc.add_note(text)


def _positive(value: float, name: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


def _non_negative(value: float, name: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
