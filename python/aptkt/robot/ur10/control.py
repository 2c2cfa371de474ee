"""ur_rtde's control client in a child process (:mod:`aptkt.robot.ur10._control_child`).

``RTDEControlInterface`` is not safe once its link drops: its own receive thread then
reconnects (it cannot be told not to: no constructor flag of ur_rtde 1.6 turns that off), and
a call made on any other thread at that moment — say, the watchdog kick of the supervision
loop, which ur_rtde answers on a broken pipe by reconnecting on the caller's thread too —
resets and reopens the same socket and replaces the state the other thread reads, with no
lock between them. Destroying the client then joins a thread that may be reconnecting. In
one process that ended in SIGSEGV (about one drop in 30 on a loaded machine) or in a thread
blocked for ever; and a client left alive kept reconnecting and took the controller's input
registers from the next connection.

So the client lives in a process of its own, and :meth:`ControlProcess.kill` ends it with
SIGKILL the moment the link is suspect: no ur_rtde code of that client runs any more, no
destructor, and the system closes its sockets, which frees the controller's registers. A
crash or a hang inside ur_rtde costs that process only; the parent sees the reply pipe close
or the call time out, and reports a lost link.

One call at a time (the caller holds the lock of :class:`~aptkt.robot.ur10.connection.
Connection`); replies carry the request's id, so the late reply of an abandoned call is
skipped.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from aptkt.errors import RobotConnectionError

__all__ = ["ControlProcess", "ControlProcessEnded", "CONNECT_TIMEOUT"]

_CHILD = Path(__file__).with_name("_control_child.py")
# Longest the client may take to connect and start its control script (ur_rtde waits up to
# 5 s for the program to run, and up to 5 s for RTDE synchronisation).
CONNECT_TIMEOUT = 30.0


class ControlProcessEnded(RuntimeError):
    """The control process ended (crashed, or was killed) before it replied."""


class _Pending:
    """Marks a reply that has not arrived yet."""


PENDING = _Pending()


class ControlProcess:
    """One ``RTDEControlInterface(host, frequency)`` in a child process.

    :meth:`request` sends a call; :meth:`reply` waits (up to a timeout) for its result, which
    is returned, raised as ``RuntimeError`` (what ur_rtde raises) or, for a process that
    ended, :class:`ControlProcessEnded`. ``connected`` is the control connection's state as
    of the last reply.
    """

    def __init__(self, host: str, frequency: float):
        import rtde_control  # the caller checked it is installed

        request_r, self._request_w = os.pipe()
        self._reply_r, reply_w = os.pipe()
        try:
            self._proc = subprocess.Popen(
                [
                    sys.executable,
                    "-I",  # no PYTHON* variables, no script directory on the path
                    str(_CHILD),
                    host,
                    repr(float(frequency)),
                    str(request_r),
                    str(reply_w),
                    str(Path(rtde_control.__file__).parent),
                    str(os.getpid()),
                ],
                pass_fds=(request_r, reply_w),
                stdin=subprocess.DEVNULL,
                # Not in our process group: Ctrl-C at a terminal (or a job's SIGTERM to the
                # group) must reach only us, while we still need the client to stop and
                # retract the arm. The process ends with us (see _control_child).
                start_new_session=True,
            )
        except BaseException:
            for fd in (self._request_w, self._reply_r):
                os.close(fd)
            raise
        finally:
            os.close(request_r)
            os.close(reply_w)
        # Closed only by release(): another thread may still be waiting on them after a kill.
        self._fds: tuple[int, ...] = (self._request_w, self._reply_r)
        self._buffer = b""
        self._next_id = 1
        self._waiting: int | None = None
        self.connected = False
        self.ended = False
        try:
            self.reply(CONNECT_TIMEOUT, want=0)
        except (RuntimeError, TimeoutError) as exc:
            self.release()
            raise RobotConnectionError(
                f"cannot connect to the UR controller at {host}: {exc}"
            ) from None

    # ------------------------------------------------------------------ calls
    def request(self, op: str, *args: Any) -> int:
        """Send one call; returns its id."""
        if self.ended:
            raise ControlProcessEnded("the control client process has ended")
        ident = self._next_id
        self._next_id += 1
        data = (json.dumps({"id": ident, "op": op, "args": list(args)}) + "\n").encode()
        try:
            while data:
                data = data[os.write(self._request_w, data) :]
        except OSError:  # the process is gone: its end of the pipe closed
            raise self._ended() from None
        self._waiting = ident
        return ident

    def reply(self, timeout: float, want: int | None = None) -> Any:
        """The result of call ``want`` (default: the last one sent), or :data:`PENDING` if it
        did not come within ``timeout`` s (``want=0``: raises ``TimeoutError`` instead)."""
        want = self._waiting if want is None else want
        deadline = time.monotonic() + timeout
        while True:
            line, _, rest = self._buffer.partition(b"\n")
            if _:
                self._buffer = rest
                message = json.loads(line)
                self.connected = bool(message.get("connected"))
                if message["id"] != want:
                    continue  # the late reply of an abandoned call
                if "error" in message:
                    if message.get("type") == "TypeError":  # a call with wrong arguments
                        raise TypeError(message["error"])
                    raise RuntimeError(message["error"])  # what ur_rtde raises
                return message.get("ok")
            left = deadline - time.monotonic()
            if left <= 0:
                if want == 0:
                    raise TimeoutError(f"no answer within {timeout:.0f} s")
                return PENDING
            if self.ended:
                raise ControlProcessEnded("the control client process has ended")
            ready, _w, _x = select.select([self._reply_r], [], [], left)
            if not ready:
                continue
            chunk = os.read(self._reply_r, 65536)
            if not chunk:
                raise self._ended()
            self._buffer += chunk

    # ------------------------------------------------------------------ ending
    def _ended(self) -> ControlProcessEnded:
        """The process closed its pipes: it ended (or is ending); say how."""
        try:
            code = self._proc.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            self.kill()
            code = self._proc.returncode
        self.ended, self.connected = True, False
        if code is not None and code < 0:
            how = f"signal {signal.Signals(-code).name}"
        else:
            how = f"exit code {code}"
        return ControlProcessEnded(f"the control client process ended ({how})")

    def close(self, timeout: float) -> None:
        """Disconnect cleanly (a healthy link only): ur_rtde's ``disconnect`` in the process,
        which then exits; killed if that takes longer than ``timeout`` s."""
        if self.ended:
            return
        try:
            self.request("close")
            self.reply(timeout)
            self._proc.wait(timeout=timeout)
        except (RuntimeError, subprocess.TimeoutExpired):
            pass
        self.kill()

    def kill(self) -> None:
        """End the process now (SIGKILL): no code of its client runs any more. Idempotent."""
        if self.ended:
            return
        try:
            self._proc.kill()
        except OSError:
            pass
        try:
            self._proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:  # pragma: no cover - SIGKILL is not refused
            pass
        self.ended, self.connected = True, False

    def release(self) -> None:
        """Kill the process (if alive) and close the pipes: the object is done with."""
        self.kill()
        fds, self._fds = self._fds, ()
        for fd in fds:
            os.close(fd)

    @property
    def pid(self) -> int:
        return self._proc.pid

    def __del__(self) -> None:
        # A process nobody can talk to any more must not keep feeding the controller.
        try:
            self.release()
        except Exception:
            pass
