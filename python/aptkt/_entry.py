"""The ``aptkt`` console script.

Until a command has parsed its arguments it has done nothing: no file is open, no robot
connected. A Ctrl-C or SIGTERM in that time (Python's imports take a second or two on a busy
machine) ends the program at once with one line and the signal's exit code, 130 or 143, rather
than an import's traceback or a silent death. :func:`aptkt.cli.main` then takes over the
signals, so that every command stops cleanly. Once it has returned, a signal is ignored: the
work is done, and Python's shutdown would otherwise let it kill the process silently.

These handlers are set by :func:`run`, which only the console script calls: importing
:mod:`aptkt`, :mod:`aptkt.cli` or this module in a program leaves its signals alone.
"""

from __future__ import annotations

import importlib
import os
import sys

try:
    # CPython's C module under `signal`: `signal` first imports enum, which on a busy machine
    # doubles the time before these handlers are set.
    signal = importlib.import_module("_signal")
except ImportError:
    signal = importlib.import_module("signal")

_LINES: dict[int, bytes] = {
    signal.SIGINT: b"aptkt: interrupted\n",
    signal.SIGTERM: b"aptkt: terminated (SIGTERM)\n",
}


def _end_at_once(signum: int, frame: object) -> None:
    # os.write and os._exit: nothing to clean up yet, and nothing Python would run on its way
    # out (a flush, an atexit hook) may raise in its place.
    os.write(2, _LINES.get(signum, b"aptkt: stopped by a signal\n"))
    os._exit(128 + signum)


def run() -> None:
    # Set here, not when this module is imported: importing it (a test importing every
    # module, say) must not change a program's signals. The console script calls this right
    # after its import.
    for signum in _LINES:
        # A signal the caller ignores stays ignored (a shell's background job ignores Ctrl-C).
        if signal.getsignal(signum) != signal.SIG_IGN:
            signal.signal(signum, _end_at_once)
    from aptkt.cli import main

    try:
        code = main()
    finally:
        # The command is over and its output written. Python restores the default handlers
        # as it shuts down, so a signal in these last milliseconds killed the process without a
        # word (exit -2) or, a little earlier, reported a finished command as interrupted.
        # Now it changes nothing.
        for signum in _LINES:
            signal.signal(signum, signal.SIG_IGN)
    sys.exit(code)
