"""The process that owns ur_rtde's control client (run as a script by
:class:`aptkt.robot.ur10.control.ControlProcess`; imports nothing of aptkt).

Why a process of its own: ``RTDEControlInterface`` reconnects by itself when its link drops,
on its own receive thread, while a call of ours may be running inside the same client on
another thread; both then reset and reopen one unguarded socket and replace the state the
other is reading (ur_rtde has no lock around them). In-process that ended in SIGSEGV or in a
thread blocked for ever. Here a crash or a hang costs only this process, which the parent
kills (SIGKILL: no ur_rtde code runs any more, the system closes its sockets) as soon as the
link is suspect.

Protocol: one JSON object per line. The parent sends ``{"id", "op", "args"}`` on the request
pipe; the reply ``{"id", "ok" | "error", "type", "connected"}`` comes on the reply pipe
(``connected``: the control connection's state after the call). The first reply, id 0, says
whether the client could be created. Usage: ``_control_child.py HOST FREQUENCY REQUEST_FD
REPLY_FD RTDE_DIR PARENT_PID``.

The op ``idle`` with ``[interval]`` turns this process's keep-alive on (``interval`` > 0) or
off (0): while it is on, the controller's RTDE watchdog is kicked every ``interval`` s between
requests. The parent turns it on while no movement is supervised. Here, and not on a thread of
the parent, because this process runs nothing else: a parent that holds its GIL for longer
than the watchdog's period (an HDF5 write, a module loaded while the arm waits) must not let
the controller stop the program of an arm at rest. During a movement the parent's supervision
loop alone feeds the watchdog, so a stalled loop still stops the arm.
"""

from __future__ import annotations

import json
import os
import select
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any


def _die_with_parent(parent: int) -> None:
    # An orphaned client would keep the controller's input registers and feed its watchdog.
    # (Not PR_SET_PDEATHSIG: that fires when the *thread* that started us ends.) A thread of
    # Python can run meanwhile: ur_rtde's calls release the GIL.
    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.2)
        os._exit(0)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def _send(fd: int, message: dict[str, Any]) -> None:
    data = (json.dumps(message) + "\n").encode()
    while data:
        data = data[os.write(fd, data) :]


def _requests(fd: int, wait: Callable[[], float | None]) -> Iterator[dict[str, Any] | None]:
    """The parent's requests, one per line, until it closes the pipe; None whenever ``wait()``
    s pass without one (``wait()`` None: no limit)."""
    buffer = b""
    while True:
        line, newline, rest = buffer.partition(b"\n")
        if newline:
            buffer = rest
            yield json.loads(line)
            continue
        ready, _, _ = select.select([fd], [], [], wait())
        if not ready:
            yield None
            continue
        chunk = os.read(fd, 65536)
        if not chunk:
            return
        buffer += chunk


def main(argv: list[str]) -> None:
    host, frequency, request_fd, reply_fd, rtde_dir, parent = argv
    # Ctrl-C and SIGTERM (a terminal's, or a job's, sent to the whole process group) are the
    # parent's to handle: it stops and retracts the arm through this process, then ends it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _die_with_parent(int(parent))
    sys.path.insert(0, rtde_dir)
    import rtde_control

    r_fd, w_fd = int(request_fd), int(reply_fd)
    try:
        control = rtde_control.RTDEControlInterface(host, float(frequency))
    except Exception as exc:  # any failure to connect is the parent's RobotConnectionError
        _send(w_fd, {"id": 0, "error": str(exc), "type": type(exc).__name__, "connected": False})
        os._exit(1)
    _send(w_fd, {"id": 0, "ok": "ready", "connected": True})
    idle_interval = 0.0  # the keep-alive's period while the arm is idle (0: off)
    next_kick = 0.0

    def until_kick() -> float | None:
        return max(0.0, next_kick - time.monotonic()) if idle_interval > 0 else None

    for request in _requests(r_fd, until_kick):
        if idle_interval > 0 and time.monotonic() >= next_kick:
            next_kick = time.monotonic() + idle_interval
            try:
                if control.isConnected() and control.isProgramRunning():
                    control.kickWatchdog()
            except Exception:  # a link going down shows in the next request's reply
                pass
        if request is None:  # (only the keep-alive's moment)
            continue
        op, args = request["op"], request["args"]
        reply: dict[str, Any] = {"id": request["id"]}
        try:
            if op == "close":
                control.disconnect()
                reply["ok"] = None
            elif op == "idle":
                idle_interval = max(0.0, float(args[0]))
                next_kick = time.monotonic() + idle_interval
                reply["ok"] = None
            elif not control.isConnected():
                # Calling into a client that is reconnecting is exactly the race: refuse.
                raise RuntimeError("the RTDE control connection is down")
            elif op == "asyncStatus":
                status = control.getAsyncOperationProgressEx()
                reply["ok"] = [int(status.operationId()), bool(status.isAsyncOperationRunning())]
            else:
                reply["ok"] = getattr(control, op)(*args)
        except Exception as exc:  # handed to the parent, which decides
            reply["error"], reply["type"] = str(exc), type(exc).__name__
        reply["connected"] = op != "close" and bool(control.isConnected())
        _send(w_fd, reply)
        if op == "close":
            break
    # Never ur_rtde's destructor: it disconnects again (0.5 s) and joins threads that may be
    # reconnecting. The system closes the sockets.
    os._exit(0)


if __name__ == "__main__":
    main(sys.argv[1:])
