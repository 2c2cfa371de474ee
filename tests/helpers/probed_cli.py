"""``aptkt`` in a process of its own, with a :class:`timing.LatenessProbe` beside it:
``python probed_cli.py REPORT ARGS...`` runs ``aptkt ARGS...`` and, as it exits (a signal's
exit included), writes to REPORT the worst lateness of its own threads from the moment its
robot connection was open until that connection began to be dropped (its teardown holds the
GIL 0.5 s by design, and is no stall of the machine's). A test that runs aptkt in a child
process measures there what the in-process tests measure in their own process: how long the
machine kept aptkt's supervision and skin reader waiting.
"""

from __future__ import annotations

import atexit
import json
import runpy
import sys
import time
from pathlib import Path

from timing import LatenessProbe

from aptkt.robot.ur10.connection import Connection


def main() -> None:
    report, argv = Path(sys.argv[1]), sys.argv[2:]
    probe = LatenessProbe().start()  # (the parameters of the in-process tests' probe)
    # Each robot connection's [opened, teardown began] (a run may open more than one).
    connected: list[list[float | None]] = []
    open_, drop_clients = Connection.open, Connection.drop_clients

    def opened(connection: Connection) -> None:
        open_(connection)
        connected.append([time.monotonic(), None])

    def dropping(connection: Connection) -> None:
        # (connect() drops a connection not yet open first: no teardown then.)
        opened_now = connection.receive is not None or connection.control is not None
        if opened_now and connected and connected[-1][1] is None:
            connected[-1][1] = time.monotonic()
        drop_clients(connection)

    Connection.open = opened  # type: ignore[method-assign]
    Connection.drop_clients = dropping  # type: ignore[method-assign]

    def write() -> None:
        worst = max((probe.worst(a, b) for a, b in connected if a is not None), default=None)
        report.write_text(json.dumps({"worst_lateness": worst, "connected": connected}))

    atexit.register(write)
    sys.argv = ["aptkt", *argv]
    runpy.run_module("aptkt.cli", run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
