"""Child processes for tests that signal them."""

from __future__ import annotations

import signal


def default_signals() -> None:
    """``preexec_fn`` of a child that a test interrupts: Ctrl-C and SIGTERM act on it as on a
    command typed at a terminal. A test runner started in the background by a shell without
    job control (``make test &``) ignores SIGINT, and its children inherit that; a command
    respects an inherited "ignore", as Python itself does."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
