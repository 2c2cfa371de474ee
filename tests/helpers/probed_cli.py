"""``aptkt`` in a process of its own, with a :class:`timing.LatenessProbe` beside it:
``python probed_cli.py REPORT ARGS...`` runs ``aptkt ARGS...`` and, as it exits (a signal's
exit included), writes to REPORT the worst lateness of its own threads from the moment its
robot connection was open until that connection began to be dropped (its teardown holds the
GIL 0.5 s by design, and is no stall of the machine's). A test that runs aptkt in a child
process measures there what the in-process tests measure in their own process: how long the
machine kept aptkt's supervision and skin reader waiting. :func:`watch_connections` marks
the same moments for the tests that run aptkt in their own process.
"""

from __future__ import annotations

import atexit
import json
import runpy
import sys
import time
from collections.abc import Callable
from pathlib import Path

from timing import LatenessProbe

from aptkt.robot.ur10.connection import Connection


def watch_connections(
    opened: Callable[[], None], teardown: Callable[[], None]
) -> Callable[[], None]:
    """Have :class:`Connection` call ``opened()`` once a connection is open and
    ``teardown()`` as one that holds clients begins to drop them (``connect()`` first drops
    the clients of a connection not yet open, as a reset: no teardown). Returns the undo."""
    open_, drop_clients = Connection.open, Connection.drop_clients

    def opening(connection: Connection) -> None:
        open_(connection)
        opened()

    def dropping(connection: Connection) -> None:
        if connection.receive is not None or connection.control is not None:
            teardown()
        drop_clients(connection)

    def undo() -> None:
        Connection.open = open_  # type: ignore[method-assign]
        Connection.drop_clients = drop_clients  # type: ignore[method-assign]

    Connection.open = opening  # type: ignore[method-assign]
    Connection.drop_clients = dropping  # type: ignore[method-assign]
    return undo


def main() -> None:
    report, argv = Path(sys.argv[1]), sys.argv[2:]
    probe = LatenessProbe().start()  # (the parameters of the in-process tests' probe)
    # Each robot connection's [opened, teardown began] ([opened] until it begins).
    connected: list[list[float]] = []

    def teardown() -> None:
        if connected and len(connected[-1]) == 1:
            connected[-1].append(time.monotonic())

    watch_connections(lambda: connected.append([time.monotonic()]), teardown)

    def write() -> None:
        worst = max((probe.worst(*window) for window in connected), default=None)
        report.write_text(json.dumps({"worst_lateness": worst, "connected": connected}))

    atexit.register(write)
    sys.argv = ["aptkt", *argv]
    runpy.run_module("aptkt.cli", run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
