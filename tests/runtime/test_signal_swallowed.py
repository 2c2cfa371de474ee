"""A Ctrl-C or SIGTERM stops a running command even when Python runs its handler where an
exception cannot propagate: a ``__del__`` or a garbage collector's weakref callback, where Python
prints "Exception ignored" and goes on. Seen under load: a SIGTERM landed in a weakref callback
and the command ran on until its caller gave up."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from processes import default_signals

PYTHON_DIR = str(Path(__file__).resolve().parents[2] / "python")
ENV = {**os.environ, "PYTHONPATH": PYTHON_DIR}
SIGNALS = pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)

# A command line with one stand-in command (``swallow``) whose code signals its own process from
# inside code that swallows exceptions; the signal's handler runs there (the loop's backward
# jumps are where Python runs pending handlers). Then the command works on for 20 s in small
# steps: unless something sends the signal again, it finishes and says so.
_CHILD = """
import argparse, gc, os, sys, time, weakref
import aptkt.cli as cli

SIG = {sig}
WHERE = {where!r}

class Swallows:
    def __del__(self):
        os.kill(os.getpid(), SIG)
        for _ in range(100_000):
            pass
        print("handler ran inside", flush=True)

class Node:
    pass

KEEP = []  # (a weakref's callback runs only if the weakref outlives its object)

def run(args):
    if WHERE == "del":
        Swallows()
    else:
        gc.disable()
        node = Node()
        node.cycle = node
        KEEP.append(weakref.ref(node, lambda _: Swallows.__del__(None)))
        del node
        gc.collect()
    for _ in range(200):
        time.sleep(0.1)
    print("ran to the end", flush=True)
    return 0

def build_parser():
    parser = argparse.ArgumentParser(prog="aptkt")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("swallow").set_defaults(func=run)
    return parser

cli.build_parser = build_parser
sys.exit(cli.main(["swallow"]))
"""


def _run(sig: int, where: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", _CHILD.format(sig=int(sig), where=where)],
        env=ENV,
        capture_output=True,
        text=True,
        timeout=60,
        preexec_fn=default_signals,
    )


@SIGNALS
@pytest.mark.parametrize("where", ["del", "weakref callback"])
def test_a_signal_in_code_that_swallows_exceptions_still_stops_the_command(sig, where):
    proc = _run(sig, where)
    line = "terminated (SIGTERM)" if sig == signal.SIGTERM else "interrupted"
    # The handler ran inside (its exception ended that code early, and was swallowed there),
    # and the command stopped all the same, the way a signal anywhere else stops it.
    assert "handler ran inside" not in proc.stdout, proc.stderr
    assert "ran to the end" not in proc.stdout, proc.stderr
    assert proc.returncode == 128 + sig, proc.stderr
    assert proc.stderr.strip().endswith(f"aptkt swallow: {line}"), proc.stderr


def test_other_exceptions_python_swallows_are_reported_as_before():
    """Only a signal's exception is sent again: any other goes to the hook that was there."""
    code = (
        "import sys, aptkt.cli as cli, argparse\n"
        "class Fails:\n"
        "    def __del__(self): raise ValueError('from __del__')\n"
        "def run(args):\n"
        "    Fails()\n"
        "    return 0\n"
        "def build_parser():\n"
        "    parser = argparse.ArgumentParser(prog='aptkt')\n"
        "    sub = parser.add_subparsers(dest='command', required=True)\n"
        "    sub.add_parser('swallow').set_defaults(func=run)\n"
        "    return parser\n"
        "cli.build_parser = build_parser\n"
        "sys.exit(cli.main(['swallow']))\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], env=ENV, capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0
    assert "Exception ignored" in proc.stderr and "ValueError: from __del__" in proc.stderr
