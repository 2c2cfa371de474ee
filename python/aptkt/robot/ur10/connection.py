"""The link to one UR controller: ur_rtde's receive and control clients, the one worker thread
that calls ``rtde_control``, the freshness of the robot data, and the controller's watchdog.

ur_rtde blocks on its own (possibly stale) state: a command sent as the link died may wait up
to 300 s for a "done" that never shows. So every control call runs on a worker thread while
the caller watches the link, and once the link is found lost nothing more is sent: the
controller's own RTDE watchdog (armed at connect) stops the program on its side. While the arm
is idle a keep-alive thread feeds that watchdog; during a movement the supervision loop does
(:meth:`Connection.kick`), so a stalled loop stops the arm too.
"""

from __future__ import annotations

import atexit
import ctypes
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any

import numpy as np

from aptkt.errors import (
    ProgramStoppedError,
    ProtectiveStopError,
    RobotConnectionError,
    RobotError,
)

__all__ = ["Connection", "RobotState"]

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
COMMAND_TIMEOUT = 10.0
# Commands ur_rtde's control script executes every cycle without a done-handshake.
_REALTIME_COMMANDS = frozenset({"speedL", "forceMode"})


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


# Clients of a dropped link, kept until the process ends (see Connection.drop_clients).
_abandoned: list[Any] = []


def _abandon(*clients: Any) -> None:
    for client in clients:
        # Disconnecting ends the control client's attempts to reconnect, which would otherwise
        # take the controller's input registers from the next connection.
        try:
            if client is not None:
                client.disconnect()
        except RuntimeError:
            pass
    with _graveyard_lock:
        _abandoned.extend(c for c in clients if c is not None)


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
        if _abandoned:
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(_abandoned))


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


class RobotState:
    """One read of the controller's state: its timestamp (and whether it is new), TCP pose,
    speed and wrench."""

    __slots__ = ("timestamp", "fresh", "pose", "speed", "force")

    def __init__(
        self, timestamp: float, fresh: bool, pose: np.ndarray, speed: np.ndarray, force: np.ndarray
    ):
        self.timestamp = timestamp
        self.fresh = fresh
        self.pose = pose
        self.speed = speed
        self.force = force


class Connection:
    """ur_rtde's clients for one controller, with link supervision.

    ``watchdog_timeout`` is how long robot data may stay unchanged before the link counts as
    lost; the controller's RTDE watchdog is armed at ``1 / watchdog_timeout`` Hz.
    ``frequency`` forces the RTDE rate (default: detected from the controller's timestamps).

    No method keeps a client in a local variable: see :meth:`drop_clients`.
    """

    def __init__(self, host: str, watchdog_timeout: float, frequency: float | None = None):
        self.host = host
        self.watchdog_timeout = watchdog_timeout
        self._requested_frequency = frequency
        self.frequency = frequency or 125.0
        self.control: Any = None
        self.receive: Any = None
        self._worker: _Worker | None = None
        #: Why the link was lost (None while it is fine): nothing more is sent once it is set.
        self.lost: str | None = None
        #: What the control script runs: "speed" | "force+speed" | "force" | "move" | None.
        self.mode: str | None = None
        #: The real-time command repeated every supervision cycle (see :meth:`command`).
        self.hold: tuple[str, tuple[Any, ...]] | None = None
        #: Set while a movement is supervised: the keep-alive thread stays out of the way.
        self.in_motion = False
        self._keepalive: threading.Thread | None = None
        self._keepalive_stop = threading.Event()
        self.reset_freshness()

    # ------------------------------------------------------------------ open / close
    def open(self) -> None:
        """Create the clients (ur_rtde uploads its control script) and the worker thread."""
        try:
            import rtde_control  # optional dependency: the ur10 extra
            import rtde_receive
        except ImportError:
            raise RobotConnectionError(
                "the UR10 backend needs the ur_rtde package: pip install 'aptkt[ur10]'"
            ) from None
        freq = -1.0 if self._requested_frequency is None else float(self._requested_frequency)
        try:
            self.receive = rtde_receive.RTDEReceiveInterface(self.host, freq, _RECEIVE_VARIABLES)
            self.control = rtde_control.RTDEControlInterface(self.host, freq)
        except RuntimeError as exc:
            self.drop_clients()
            raise RobotConnectionError(
                f"cannot connect to the UR controller at {self.host}: {exc}"
            ) from None
        self.lost = None
        self._worker = _Worker(f"ur10-rtde-control-{self.host}")
        self.frequency = self._detect_frequency()

    def arm_watchdog(self) -> None:
        """Arm the controller's RTDE watchdog and start feeding it while the arm is idle."""
        self.command("setWatchdog", 1.0 / self.watchdog_timeout)
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
            ts = float(self.receive.getTimestamp())
            if not stamps or ts != stamps[-1]:
                stamps.append(ts)
            time.sleep(0.0005)
        steps = [b - a for a, b in zip(stamps, stamps[1:]) if b > a]
        if not steps:
            raise self.lose("the controller sends no data")
        return 500.0 if min(steps) < 0.005 else 125.0

    def stop_keepalive(self) -> None:
        self._keepalive_stop.set()
        if self._keepalive is not None:
            self._keepalive.join(timeout=2.0)
            self._keepalive = None

    def disconnect(self) -> None:
        """End the worker and destroy the clients (the arm must be stopped first)."""
        if self._worker is not None:
            self._worker.close()
            # A call still spinning inside ur_rtde (it holds the client) would keep the old
            # connection and its input registers alive: let it end (ur_rtde gives up after
            # at most 4 s on a live link). An abandoned worker is not waited for.
            self._worker.thread.join(timeout=COMMAND_TIMEOUT)
            self._worker = None
        self.drop_clients()
        _sweep_graveyard()

    def drop_clients(self) -> None:
        if self.lost is not None and self.control is not None:
            # After a dropped link ur_rtde's clients are never destroyed: their background
            # threads (the receive loop, the control client's reconnect attempts) still use
            # the client when the link drops, and its destructor tearing them down then crashed
            # the process (SIGSEGV in 4 of 6 drops, about 0.5 s after the drop). A dead client
            # holds a few kB and two sockets until the process ends.
            _abandon(self.control, self.receive)
            self.control = self.receive = None
            return
        # ur_rtde's destructors disconnect and sleep 0.5 s each *with the GIL held*; an
        # explicit disconnect() first would only add another 0.5 s per client. They must run
        # here: a client kept alive elsewhere (say, by a local variable of a frame in some
        # exception's traceback) is destroyed later by the garbage collector, and that 0.5 s
        # GIL stall inside another connection's supervision loop lets the controller's
        # watchdog stop the arm. Hence no method keeps a client in a local variable.
        self.control = self.receive = None

    @property
    def connected(self) -> bool:
        return self.control is not None and self.lost is None

    # ------------------------------------------------------------------ link health
    def reset_freshness(self) -> None:
        self.last_ts: float | None = None
        self.last_fresh = time.monotonic()

    def require_link(self) -> None:
        if self.control is None:
            raise RobotConnectionError(f"not connected to the UR controller at {self.host}")
        if self.lost is not None:
            raise RobotConnectionError(
                f"the link to {self.host} was lost ({self.lost}); call recover()"
            )

    def link_ok(self) -> bool:
        """Whether it is safe to send a command: one sent on a dead link blocks for minutes."""
        try:
            if not (self.control.isConnected() and self.receive.isConnected()):
                return False
            ts = float(self.receive.getTimestamp())
        except RuntimeError:
            return False
        now = time.monotonic()
        if ts != self.last_ts:
            self.last_ts, self.last_fresh = ts, now
            return True
        return now - self.last_fresh <= self.watchdog_timeout

    def lose(self, why: str) -> RobotConnectionError:
        """Mark the link lost (nothing more is sent) and return the error to raise."""
        self.lost = why
        self.mode = None
        self.hold = None
        return RobotConnectionError(
            f"lost the link to the UR controller at {self.host}: {why}. No further commands are sent; "
            f"the controller's RTDE watchdog stops the program within {self.watchdog_timeout} s"
        )

    def read(self) -> RobotState:
        """Read the controller's state once; raises on a lost link, a protective stop or a
        stopped program."""
        now = time.monotonic()
        try:
            if not (self.receive.isConnected() and self.control.isConnected()):
                raise self.lose("the RTDE connection closed")
            ts = float(self.receive.getTimestamp())
            fresh = ts != self.last_ts
            if fresh:
                self.last_ts, self.last_fresh = ts, now
            elif now - self.last_fresh > self.watchdog_timeout:
                raise self.lose(f"no fresh robot data for {now - self.last_fresh:.2f} s (watchdog)")
            if self.receive.isProtectiveStopped() or self.receive.isEmergencyStopped():
                raise ProtectiveStopError(
                    "the controller entered a protective stop; the arm is stopped"
                )
            if self.receive.getRuntimeState() != _PLAYING:
                raise ProgramStoppedError(
                    "the control program on the controller stopped; the arm is stopped"
                )
            pose = np.asarray(self.receive.getActualTCPPose(), dtype=float)
            speed = np.asarray(self.receive.getActualTCPSpeed(), dtype=float)
            force = np.asarray(self.receive.getActualTCPForce(), dtype=float)
        except RuntimeError as exc:
            raise self.lose(str(exc)) from None
        return RobotState(ts, fresh, pose, speed, force)

    def peek_pose(self) -> np.ndarray:
        """The TCP pose for planning, without limit checks (nothing moves yet)."""
        self.require_link()
        if not self.link_ok():
            raise self.lose("no fresh robot data")
        try:
            return np.asarray(self.receive.getActualTCPPose(), dtype=float)
        except RuntimeError as exc:
            raise self.lose(str(exc)) from None

    def async_status(self) -> tuple[int, bool]:
        """``(operation id, still running)`` of the controller's last asynchronous command."""
        try:
            status = self.control.getAsyncOperationProgressEx()
            return int(status.operationId()), bool(status.isAsyncOperationRunning())
        except RuntimeError as exc:
            raise self.lose(str(exc)) from None

    def protective_stopped(self) -> bool:
        try:
            return bool(self.receive.isProtectiveStopped())
        except RuntimeError:
            return False

    def unlock_protective_stop(self) -> None:
        """Unlock a protective stop through the dashboard server."""
        import dashboard_client  # optional dependency: part of ur_rtde

        db = dashboard_client.DashboardClient(self.host)
        try:
            db.connect()
            db.unlockProtectiveStop()
        except RuntimeError as exc:
            raise ProtectiveStopError(f"cannot unlock the protective stop: {exc}") from None
        finally:
            db.disconnect()

    # ------------------------------------------------------------------ commands
    def command(self, name: str, *args: Any) -> Any:
        """Send one rtde_control command on a checked link; a refusal raises the reason."""
        # A real-time command (speedL, forceMode) is only a value in the command register: the
        # next data package would overwrite it before the control script's next cycle reads
        # it. So it is repeated every supervision cycle instead of the watchdog kick.
        self.hold = (name, args) if name in _REALTIME_COMMANDS else None
        self.require_link()
        if not self.link_ok():
            raise self.lose(f"no fresh robot data before sending {name}")
        result = self.call(name, *args)
        if result is False:
            self.explain(name)
        return result

    def kick(self) -> None:
        """Feed the controller's watchdog: repeat the held real-time command, or kick."""
        name, args = self.hold or ("kickWatchdog", ())
        if self.call(name, *args) is False:
            self.explain(name)

    def call(self, name: str, *args: Any) -> Any:
        """Run one rtde_control method on the worker thread while watching the link.

        ur_rtde blocks on its own (possibly stale) state: a refused command returns within
        milliseconds, but one sent as the link died may wait up to 300 s, and one racing a
        program stop spins up to 4 s. So: give up at once when the link goes stale, and look
        at the controller state after a short grace period.
        """
        worker = self._worker
        if worker is None or self.control is None:
            raise RobotConnectionError(f"not connected to the UR controller at {self.host}")
        future = worker.submit(getattr(self.control, name), *args)
        start = time.monotonic()
        while True:
            try:
                return future.result(timeout=0.01)
            except FutureTimeout:
                pass
            except RuntimeError as exc:
                raise self.lose(f"{name} failed: {exc}") from None
            waited = time.monotonic() - start
            if not self.link_ok():
                self._abandon_worker()
                raise self.lose(f"{name} was sent on a link without fresh data")
            if waited > 0.2:
                try:
                    if self.receive.isProtectiveStopped() or self.receive.isEmergencyStopped():
                        raise ProtectiveStopError(
                            f"the controller is in a protective/emergency stop ({name})"
                        )
                    if self.receive.getRuntimeState() != _PLAYING:
                        raise ProgramStoppedError(
                            f"the control program is not running on the controller ({name})"
                        )
                except RuntimeError as exc:
                    raise self.lose(str(exc)) from None
            if waited > COMMAND_TIMEOUT:
                self._abandon_worker()
                raise self.lose(f"{name} did not complete within {COMMAND_TIMEOUT:.0f} s")

    def _abandon_worker(self) -> None:
        # The stuck call ends on ur_rtde's own timeout; its thread then exits. Nothing else
        # is queued behind it: a lost link sends nothing more.
        if self._worker is not None:
            self._worker.close()
            _bury(self._worker.thread, self.control)
            self._worker = None

    def explain(self, name: str) -> None:
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
                if not (self.control.isConnected() and self.receive.isConnected()):
                    raise self.lose(f"the RTDE connection closed ({name} refused)")
                ts = float(self.receive.getTimestamp())
                first_ts = ts if first_ts is None else first_ts
                if self.receive.isProtectiveStopped() or self.receive.isEmergencyStopped():
                    raise ProtectiveStopError(
                        f"the controller is in a protective/emergency stop ({name} refused)"
                    )
                # A protective stop pauses the program too: only call it a stopped program if
                # no protective stop shows up within the grace period.
                stopped = (
                    self.receive.getRuntimeState() != _PLAYING
                    or not self.control.isProgramRunning()
                )
            except RuntimeError as exc:
                raise self.lose(str(exc)) from None
            if time.monotonic() > deadline:
                if ts == first_ts:
                    raise self.lose(f"no fresh robot data after {name} was refused")
                if stopped:
                    raise ProgramStoppedError(
                        f"the control program is not running on the controller ({name} refused)"
                    )
                raise RobotError(f"the controller refused {name}")
            time.sleep(0.002)

    def _keep_alive(self) -> None:
        # Feeds the controller's watchdog while no movement is supervised. During movements the
        # supervision loop feeds it, so a stalled loop lets the controller stop the arm.
        interval = self.watchdog_timeout / 5.0
        while not self._keepalive_stop.wait(interval):
            worker = self._worker
            if self.in_motion or self.lost is not None or worker is None:
                continue
            try:
                if self.receive.getRuntimeState() != _PLAYING:
                    continue
                # Through the worker, so it never interleaves with a command; never waits
                # long: a stuck worker is the supervision's business.
                worker.submit(self.control.kickWatchdog).result(timeout=interval)
            except (
                RuntimeError,
                AttributeError,
                FutureTimeout,
            ):  # AttributeError: closed meanwhile
                pass
