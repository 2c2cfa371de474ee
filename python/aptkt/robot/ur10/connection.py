"""The link to one UR controller: ur_rtde's receive client, its control client (in a process of
its own, :mod:`aptkt.robot.ur10.control`), the freshness of the robot data, and the
controller's watchdog.

ur_rtde blocks on its own (possibly stale) state: a command sent as the link died may wait up
to 300 s for a "done" that never shows. So every control call is sent to the control process
while the caller watches the link, and once the link is suspect (stale data, a closed
connection, a call that does not return) the control process is killed and nothing more is
sent: the controller's own RTDE watchdog (armed at connect) stops the program on its side.
While the arm is idle the control process feeds that watchdog itself (a keep-alive that no
work of this process can delay); during a movement only the supervision loop does
(:meth:`Connection.kick`), so a stalled loop stops the arm too. One lock makes every control
call exclusive.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from aptkt.errors import (
    ProgramStoppedError,
    ProtectiveStopError,
    RobotConnectionError,
    RobotError,
)
from aptkt.robot.ur10.control import PENDING, ControlProcess

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
#: Reads of a packet's values before taking them as they are: a retry needs a new packet to
#: arrive (every 8 ms) during the microseconds the reads take, so a third in a row only
#: happens to a host that keeps stalling, and it must not keep the supervision waiting.
_CONSISTENT_READ_TRIES = 3
#: Gaps between RTDE timestamps, all multiples of 8 ms, that make a controller a 125 Hz one: a
#: 500 Hz controller shows a shorter one among 8 unless each gap happens to span 4k packets
#: (about 1 in 4 each on a host missing packets at random: (1/4)^8 = 1.5e-5).
_FREQUENCY_GAPS = 8
#: How long data that has looked unchanged for longer than the watchdog is looked at again
#: before the link counts as lost (s; at least three of the controller's periods): ur_rtde's
#: receiving thread runs in this process, so after a stall of the process it may not yet have
#: read what arrived meanwhile. A lost link stays unchanged; a late thread catches up at once.
_SECOND_LOOK = 0.05
# Commands ur_rtde's control script executes every cycle without a done-handshake.
_REALTIME_COMMANDS = frozenset({"speedL", "forceMode"})


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

    The link's states: closed (``control is None``) → open (``lost is None``) → lost (``lost``
    says why; the control process is killed, nothing more is sent) → closed. Only
    :meth:`open` leaves "lost", with new clients.

    No method keeps the receive client in a local variable: see :meth:`drop_clients`.
    """

    def __init__(self, host: str, watchdog_timeout: float, frequency: float | None = None):
        self.host = host
        self.watchdog_timeout = watchdog_timeout
        self._requested_frequency = frequency
        self.frequency = frequency or 125.0
        self.control: ControlProcess | None = None
        self.receive: Any = None
        #: Why the link was lost (None while it is fine): nothing more is sent once it is set.
        self.lost: str | None = None
        #: What the control script runs: "speed" | "force+speed" | "force" | "move" | None.
        self.mode: str | None = None
        #: The real-time command repeated every supervision cycle (see :meth:`command`).
        self.hold: tuple[str, tuple[Any, ...]] | None = None
        self._in_motion = False
        # Held for every exchange with the control process. Re-entrant: Ctrl-C or SIGTERM
        # raises in the main thread, and one that lands between `acquire()` returning and
        # the `try` that releases it leaves the lock held by that thread for good; with a
        # plain lock its own stop and teardown then waited forever (seen: a signal test's
        # aptkt hung in `drop_clients`). Other threads are still kept out.
        self._calls = threading.RLock()
        self.reset_freshness()

    # ------------------------------------------------------------------ open / close
    def open(self) -> None:
        """Create the clients (ur_rtde uploads its control script)."""
        try:
            import rtde_control  # noqa: F401 - optional dependency: the ur10 extra
            import rtde_receive
        except ImportError:
            raise RobotConnectionError(
                "the UR10 backend needs the ur_rtde package: pip install 'aptkt[ur10]'"
            ) from None
        freq = -1.0 if self._requested_frequency is None else float(self._requested_frequency)
        try:
            self.receive = rtde_receive.RTDEReceiveInterface(self.host, freq, _RECEIVE_VARIABLES)
        except RuntimeError as exc:
            raise RobotConnectionError(
                f"cannot connect to the UR controller at {self.host}: {exc}"
            ) from None
        try:
            self.control = ControlProcess(self.host, freq)
        except BaseException:
            self.drop_clients()
            raise
        self.lost = None
        self.frequency = self._detect_frequency()

    def arm_watchdog(self) -> None:
        """Arm the controller's RTDE watchdog, and have the control process feed it while the
        arm is idle."""
        self.command("setWatchdog", 1.0 / self.watchdog_timeout)
        self._in_motion = False
        self.call("idle", self.keepalive_interval)

    @property
    def keepalive_interval(self) -> float:
        """How often the control process kicks the watchdog while the arm is idle (s): five
        kicks per watchdog period."""
        return self.watchdog_timeout / 5.0

    @property
    def in_motion(self) -> bool:
        """Whether a movement is supervised: then the supervision loop alone feeds the
        controller's watchdog, and the control process's keep-alive is off."""
        return self._in_motion

    @in_motion.setter
    def in_motion(self, moving: bool) -> None:
        if moving == self._in_motion:
            return
        self._in_motion = moving
        if moving:
            self.call("idle", 0.0)  # before the movement's first command
        else:
            self._set_keepalive(self.keepalive_interval)

    def _set_keepalive(self, interval: float) -> None:
        """Have the control process kick the watchdog every ``interval`` s while idle (0: not
        at all), if the link is up; a fault of the link is reported by the next command."""
        if self.control is not None and self.lost is None and not self.control.ended:
            try:
                self.call("idle", interval)
            except RobotError:
                pass

    def _detect_frequency(self) -> float:
        """The controller's RTDE rate from its own timestamps: 500 Hz (e-series) or 125 Hz
        (CB3). A slow host misses packets, so two stamps read in a row may be several periods
        apart; but every gap is a whole number of periods, and a gap of 2, 4 or 6 ms — any that
        is not a multiple of 8 ms — can only come from 500 Hz. Stamps are read until one shows
        up, or for a second (a CB3 shows none)."""
        if self._requested_frequency:
            return float(self._requested_frequency)
        last: float | None = None
        gaps = 0
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            ts = float(self.receive.getTimestamp())
            if last is not None and ts > last:
                gaps += 1
                if round((ts - last) / 0.002) % 4:
                    return 500.0
                if gaps >= _FREQUENCY_GAPS:
                    break
            if last is None or ts > last:
                last = ts
            time.sleep(0.0005)
        if not gaps:
            raise self.lose("the controller sends no data")
        return 125.0

    def stop_keepalive(self) -> None:
        """The control process stops feeding the watchdog (before the program is stopped)."""
        self._set_keepalive(0.0)

    def disconnect(self) -> None:
        """End the control process and destroy the receive client (the arm must be stopped
        first; the keep-alive thread too)."""
        self.drop_clients()

    def drop_clients(self) -> None:
        control, self.control = self.control, None
        if control is not None:
            if self.lost is not None:
                control.kill()  # a suspect link: SIGKILL now, no ur_rtde code runs any more
            with self._calls:  # a call still waiting on the process ends with it
                if not control.ended:
                    control.close(timeout=2.0)  # ur_rtde's own disconnect, in its process
                control.release()
        # ur_rtde's receive client never reconnects by itself: after a drop its thread has
        # ended, so destroying it only joins that thread. Its destructor disconnects and
        # sleeps 0.5 s *with the GIL held*; an explicit disconnect() first would only add
        # another 0.5 s. It must run here: a client kept alive elsewhere (say, by a local
        # variable of a frame in some exception's traceback) is destroyed later by the
        # garbage collector, and that 0.5 s GIL stall inside another connection's
        # supervision loop lets the controller's watchdog stop the arm. Hence no method keeps
        # the client in a local variable.
        self.receive = None

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

    def _control_up(self) -> bool:
        control = self.control
        return control is not None and control.connected and not control.ended

    def link_ok(self) -> bool:
        """Whether it is safe to send a command: one sent on a dead link blocks for minutes."""
        try:
            if not (self._control_up() and self.receive.isConnected()):
                return False
            ts = float(self.receive.getTimestamp())
            now = time.monotonic()
            if ts == self.last_ts and now - self.last_fresh > self.watchdog_timeout:
                (ts,), now = self._second_look(lambda: (float(self.receive.getTimestamp()),))
        except (RuntimeError, AttributeError):  # AttributeError: closed meanwhile
            return False
        if ts != self.last_ts:
            self.last_ts, self.last_fresh = ts, now
            return True
        return now - self.last_fresh <= self.watchdog_timeout

    def _second_look(self, read: Callable[[], tuple[Any, ...]]) -> tuple[tuple[Any, ...], float]:
        """``read()`` (its first value the packet's timestamp) again until the timestamp
        changes, for :data:`_SECOND_LOOK` s at most (three periods, if the controller's are
        longer); returns the last values read and when."""
        deadline = time.monotonic() + max(_SECOND_LOOK, 3.0 / self.frequency)
        while True:
            values = read()
            now = time.monotonic()
            if values[0] != self.last_ts or now >= deadline:
                return values, now
            time.sleep(0.001)

    def lose(self, why: str) -> RobotConnectionError:
        """Mark the link lost, end the control process (nothing more is sent) and return the
        error to raise."""
        if self.lost is None:
            self.lost = why
        self.mode = None
        self.hold = None
        control = self.control
        if control is not None:
            control.kill()
        return RobotConnectionError(
            f"lost the link to the UR controller at {self.host}: {why}. No further commands are sent; "
            f"the controller's RTDE watchdog stops the program within {self.watchdog_timeout} s"
        )

    def read(self) -> RobotState:
        """Read the controller's state once; raises on a lost link, a protective stop or a
        stopped program."""
        now = time.monotonic()
        try:
            if not self.receive.isConnected():
                raise self.lose("the RTDE connection closed")
            if not self._control_up():
                raise self.lose("the RTDE control connection closed")
            ts, pose, speed, force = self._consistent_state()
            if ts == self.last_ts and now - self.last_fresh > self.watchdog_timeout:
                (ts, pose, speed, force), now = self._second_look(self._consistent_state)
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
        except RuntimeError as exc:
            raise self.lose(str(exc)) from None
        return RobotState(ts, fresh, pose, speed, force)

    def _consistent_state(self) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """Timestamp, pose, speed and force of one packet. ur_rtde's receiving thread replaces
        its state between two getter calls whenever a packet arrives (every 8 ms), so values
        read one by one may come from two packets: a pose one control period ahead of its
        timestamp. Read again while the timestamp changed under the reads."""
        ts = float(self.receive.getTimestamp())
        for _ in range(_CONSISTENT_READ_TRIES):
            pose = np.asarray(self.receive.getActualTCPPose(), dtype=float)
            speed = np.asarray(self.receive.getActualTCPSpeed(), dtype=float)
            force = np.asarray(self.receive.getActualTCPForce(), dtype=float)
            after = float(self.receive.getTimestamp())
            if after == ts:
                break
            ts = after
        return ts, pose, speed, force

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
        self.require_link()
        ident, running = self.call("asyncStatus")
        return int(ident), bool(running)

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
        """Run one rtde_control method in the control process while watching the link.

        ur_rtde blocks on its own (possibly stale) state: a refused command returns within
        milliseconds, but one sent as the link died may wait up to 300 s, and one racing a
        program stop spins up to 4 s. So: give up at once when the link goes stale, and look
        at the controller state after a short grace period.
        """
        if not self._calls.acquire(timeout=COMMAND_TIMEOUT + 1.0):
            raise self.lose(f"{name}: the control client stayed busy")
        try:
            return self._call(name, args)
        finally:
            self._calls.release()

    def _call(self, name: str, args: tuple[Any, ...]) -> Any:
        control = self.control
        if control is None:
            raise RobotConnectionError(f"not connected to the UR controller at {self.host}")
        if self.lost is not None or control.ended:
            raise self.lose(self.lost or "the control client process has ended")
        try:
            control.request(name, *args)
            start = time.monotonic()
            while True:
                result = control.reply(0.01)
                if result is not PENDING:
                    return result
                waited = time.monotonic() - start
                if not self.link_ok():
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
                    raise self.lose(f"{name} did not complete within {COMMAND_TIMEOUT:.0f} s")
        except RuntimeError as exc:  # ur_rtde's error, or the process ended (crashed)
            raise self.lose(f"{name} failed: {exc}") from None

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
                if not (self._control_up() and self.receive.isConnected()):
                    raise self.lose(f"the RTDE connection closed ({name} refused)")
                ts = float(self.receive.getTimestamp())
                first_ts = ts if first_ts is None else first_ts
                if self.receive.isProtectiveStopped() or self.receive.isEmergencyStopped():
                    raise ProtectiveStopError(
                        f"the controller is in a protective/emergency stop ({name} refused)"
                    )
                # A protective stop pauses the program too: only call it a stopped program if
                # no protective stop shows up within the grace period.
                stopped = self.receive.getRuntimeState() != _PLAYING
            except RuntimeError as exc:
                raise self.lose(str(exc)) from None
            if time.monotonic() > deadline:
                if ts == first_ts:
                    raise self.lose(f"no fresh robot data after {name} was refused")
                if stopped or not self.call("isProgramRunning"):
                    raise ProgramStoppedError(
                        f"the control program is not running on the controller ({name} refused)"
                    )
                raise RobotError(f"the controller refused {name}")
            time.sleep(0.002)
