"""A Ctrl-C or SIGTERM while the ``aptkt`` console script is still starting (its imports take a
second or two on a busy machine) ends it with one line and the signal's exit code, never an
import's traceback or a silent death."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from processes import default_signals

PYTHON_DIR = str(Path(__file__).resolve().parents[2] / "python")
ENV = {**os.environ, "PYTHONPATH": PYTHON_DIR}
LINES = {signal.SIGINT: "aptkt: interrupted", signal.SIGTERM: "aptkt: terminated (SIGTERM)"}
SIGNALS = pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)


def _run_with_stand_in_command(main: str, preexec_fn=default_signals):
    """``aptkt._entry.run()`` in a child whose ``aptkt.cli`` is a stand-in with the given
    ``main`` (a lambda's source, with os, sys and time imported)."""
    code = (
        "import os, sys, time, types; "
        "cli = sys.modules['aptkt.cli'] = types.ModuleType('aptkt.cli'); "
        f"cli.main = {main}; "
        "import aptkt._entry; aptkt._entry.run()"
    )
    return subprocess.run(
        [sys.executable, "-c", code],
        env=ENV,
        capture_output=True,
        text=True,
        timeout=60,
        preexec_fn=preexec_fn,
    )


@SIGNALS
def test_a_signal_before_the_command_takes_over_ends_with_one_line(sig):
    # Deterministic: a stand-in for the command line that is signalled while it (endlessly)
    # starts, before it sets its own handlers.
    proc = _run_with_stand_in_command(f"lambda: (os.kill(os.getpid(), {int(sig)}), time.sleep(30))")
    assert proc.returncode == 128 + sig
    assert proc.stderr == LINES[sig] + "\n"


def _loaded(pid: int, library: str) -> bool:
    try:
        return library in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc (Linux)")
@SIGNALS
@pytest.mark.parametrize("after", [0.0, 0.05, 0.2])
def test_a_signal_while_the_command_starts_is_one_line_and_leaves_nothing(tmp_path, sig, after):
    """Signalled ``after`` seconds after the compiled core was loaded: the command's modules
    are being imported, or its arguments parsed, or it has just begun."""
    out = tmp_path / "demo"
    proc = subprocess.Popen(
        [sys.executable, "-c", "from aptkt._entry import run; run()", "demo", "-o", str(out)],
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_signals,
    )
    try:
        while proc.poll() is None and not _loaded(proc.pid, "_core.abi3.so"):
            time.sleep(0.002)
        time.sleep(after)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    lines = err.strip().splitlines()
    assert proc.returncode == 128 + sig, err
    assert len(lines) == 1 and "Traceback" not in err, err
    # Still starting, or the demo's own handling (which may say where it stopped).
    said = LINES[sig].removeprefix("aptkt: ")
    assert lines[0] == LINES[sig] or lines[0].startswith(f"aptkt demo: {said}"), err
    # Whatever the demo had begun, an interrupted start leaves no empty output directory.
    assert not out.exists() or any(out.iterdir())


def test_importing_the_entry_point_leaves_a_programs_signals_alone():
    code = (
        "import signal; "
        "before = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)]; "
        "import aptkt._entry; "
        "assert [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)] == before"
    )
    subprocess.run([sys.executable, "-c", code], env=ENV, check=True, timeout=60)


@SIGNALS
def test_a_signal_the_caller_ignores_stays_ignored(sig):
    """A shell's background job ignores Ctrl-C: aptkt keeps it so, start-up and command."""

    def ignore() -> None:
        default_signals()
        signal.signal(sig, signal.SIG_IGN)

    proc = _run_with_stand_in_command(
        f"lambda: (os.kill(os.getpid(), {int(sig)}), print('still here') or 0)[1]",
        preexec_fn=ignore,
    )
    assert proc.returncode == 0 and proc.stdout == "still here\n", proc.stderr


@SIGNALS
def test_a_signal_as_the_finished_command_exits_changes_nothing(sig):
    """The command has returned and written its output: a signal while Python shuts down (here
    from an exit hook) neither kills the process silently nor calls it interrupted."""
    proc = _run_with_stand_in_command(
        "lambda: (__import__('atexit').register(os.kill, os.getpid(), "
        f"{int(sig)}), print('done') or 3)[1]"
    )
    assert (proc.returncode, proc.stdout, proc.stderr) == (3, "done\n", "")
