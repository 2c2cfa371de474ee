"""A worker process killed in the middle of a multi-process generation: the command ends in one
error line (no traceback), the file keeps what was written, and ``--resume`` completes it to the
same bytes as an undisturbed run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aptkt.data import DatasetReader

# 180 trials: a few seconds of simulation on two workers, so the kill lands mid-generation.
ARGS = ["--objects", "towel,cork_board,rough_sponge", "--actions", "P1,S1", "-n", "30"]
ARGS += ["--seed", "3", "--no-progress"]


def _children(pid: int) -> list[int]:
    kids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            # The command name may hold spaces and parentheses: the fields follow the last ")".
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                kids.append(int(entry.name))
    return kids


def _aptkt(*argv: str) -> list[str]:
    return [sys.executable, "-m", "aptkt.cli", "dataset", "generate", *argv]


def _keys(path: Path) -> list[tuple[str, str, int]]:
    with DatasetReader(path) as rd:
        return sorted(rd.keys())


@pytest.mark.slow
def test_a_killed_worker_is_one_error_line_and_resume_completes_the_file(tmp_path):
    out = tmp_path / "gen.h5"
    proc = subprocess.Popen(
        _aptkt("-o", str(out), "-j", "2", *ARGS),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    # Wait for the spawned workers (and the resource tracker) to appear, then kill one
    # that is simulating: the first child whose command line is a multiprocessing spawn.
    victim = None
    deadline = time.monotonic() + 120
    while victim is None and time.monotonic() < deadline and proc.poll() is None:
        for kid in _children(proc.pid):
            try:
                cmd = (Path("/proc") / str(kid) / "cmdline").read_bytes()
            except OSError:
                continue
            if b"spawn_main" in cmd:
                victim = kid
                break
        time.sleep(0.05)
    assert victim is not None, "no worker process appeared"
    time.sleep(0.3)  # let it start simulating
    os.kill(victim, signal.SIGKILL)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 1, err
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("aptkt dataset generate: error: "), err
    assert "worker process died" in lines[0] and "--resume" in lines[0], err

    resumed = subprocess.run(_aptkt("-o", str(out), "--resume", *ARGS), capture_output=True)
    assert resumed.returncode == 0, resumed.stderr
    reference = tmp_path / "reference.h5"
    subprocess.run(_aptkt("-o", str(reference), *ARGS), check=True, capture_output=True)
    assert _keys(out) == _keys(reference) and len(_keys(out)) == 180
    with DatasetReader(out) as a, DatasetReader(reference) as b:
        where = {key: i for i, key in enumerate(a.keys())}
        for j, key in enumerate(b.keys()):
            i = where[key]
            assert a.index[i]["start_ns"] == b.index[j]["start_ns"]
            raw_a, raw_b = a.raw(i), b.raw(j)
            assert raw_a.keys() == raw_b.keys()
            for name in raw_b:
                assert (raw_a[name] == raw_b[name]).all(), (key, name)


def _alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _survivors(workers: list[int]) -> list[int]:
    """The workers still alive 15 s after their parent died (killed, so that none is left
    behind by the test)."""
    deadline = time.monotonic() + 15
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [w for w in workers if _alive(w)]
    for w in left:
        os.kill(w, signal.SIGKILL)
    return left


def test_workers_end_when_their_parent_is_killed(tmp_path):
    """SIGKILL of the command itself (no chance to shut its pool down): its simulating workers
    end within seconds instead of waiting on their pipe for ever (they lived on for an hour)."""
    proc = subprocess.Popen(
        _aptkt("-o", str(tmp_path / "gen.h5"), "-j", "2", *ARGS),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    workers: list[int] = []
    deadline = time.monotonic() + 120
    while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
        workers = [
            kid
            for kid in _children(proc.pid)
            if b"spawn_main" in (Path("/proc") / str(kid) / "cmdline").read_bytes()
        ]
        time.sleep(0.05)
    assert len(workers) >= 2, "the workers never started"
    time.sleep(1.0)  # (their initializer, which starts the watch, has run)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    left = _survivors(workers)
    assert not left, f"workers {left} outlived their killed parent"


_KILLED_WHILE_STARTING = """
import multiprocessing, os, signal, time

def late_start():
    time.sleep(1.5)  # the parent is gone before the watch begins
    from aptkt.runtime.worker_start import exit_with_parent
    exit_with_parent()

if __name__ == "__main__":
    # As aptkt's executors start their workers: their task queue stays open among them.
    import concurrent.futures as cf

    pool = cf.ProcessPoolExecutor(
        2, mp_context=multiprocessing.get_context("spawn"), initializer=late_start
    )
    for _ in range(2):
        pool.submit(time.sleep, 0)
    time.sleep(0.5)  # the workers have their queues; their initializer has not run
    print(" ".join(str(p) for p in pool._processes), flush=True)
    os.kill(os.getpid(), signal.SIGKILL)
"""


def test_workers_end_when_their_parent_dies_before_they_watch_it(tmp_path):
    """The parent killed while its workers still start: they end all the same (they knew
    their parent by what the process that adopted them is, and lived on)."""
    script, out = tmp_path / "parent.py", tmp_path / "workers.txt"
    script.write_text(_KILLED_WHILE_STARTING)
    with out.open("w") as fh:  # (a pipe would stay open as long as a leaked worker lives)
        code = subprocess.run([sys.executable, str(script)], stdout=fh, timeout=60).returncode
    assert code == -signal.SIGKILL
    workers = [int(p) for p in out.read_text().split()]
    assert len(workers) == 2
    left = _survivors(workers)
    assert not left, f"workers {left} outlived a parent killed while they started"
