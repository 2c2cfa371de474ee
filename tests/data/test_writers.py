"""What a writer may touch: only regular files (a device, a FIFO, a socket or a directory at a
data set's name is refused, never renamed away or replaced), and one writer per data set at a
time, across processes (a second writer, a resume, a repair or a feature extraction is refused
naming the first; a lock left by a dead writer is taken over)."""

from __future__ import annotations

import json
import os
import socket
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aptkt.actions import PAPER_ACTIONS
from aptkt.cli import main
from aptkt.data import DatasetReader, DatasetWriter, repair
from aptkt.data.lock import WriterLock, lock_path
from aptkt.errors import DatasetError
from aptkt.runtime.generation import GenerationPlan, generate

OBJECTS = ("towel", "cork_board")
PLAN = ["--objects", ",".join(OBJECTS), "--actions", "P1,S1", "--seed", "3", "--no-progress"]


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("writers") / "small.h5"
    generate(path, GenerationPlan(OBJECTS, (PAPER_ACTIONS["P1"],), 2, seed=3), progress=False)
    return path


# -- only regular files are ours -----------------------------------------------------------------
KINDS = ["fifo", "device", "socket", "directory"] + (["mknod"] if os.geteuid() == 0 else [])


def make(kind: str, path: Path) -> Path:
    """A ``kind`` that is not a regular file at ``path``. ("device": a link to /dev/null, which
    any user may make; "mknod": the device node itself, as root.)"""
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "device":
        path.symlink_to(os.devnull)
    elif kind == "mknod":
        os.mknod(path, 0o644 | stat.S_IFCHR, os.makedev(1, 3))
    elif kind == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(path))
        s.close()
    else:
        path.mkdir()
    return path


def what(path: Path) -> tuple[int, int]:
    """The file type and the inode at ``path`` (not following a link): unchanged means
    neither renamed away nor replaced."""
    st = os.lstat(path)
    return stat.S_IFMT(st.st_mode), st.st_ino


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("kind", KINDS)
def test_no_command_touches_what_is_not_a_regular_file(kind, small, tmp_path, capsys):
    # The report: `dataset info` advised a repair of a device node, `dataset repair` renamed
    # it to .crashed and wrote an HDF5 file in its place (exit 0), as did `generate --resume`.
    node = make(kind, tmp_path / "node")
    before = what(node)
    commands = {
        "info": ["dataset", "info", str(node)],
        "repair": ["dataset", "repair", str(node)],
        "repair --no-backup": ["dataset", "repair", str(node), "--no-backup"],
        "resume": ["dataset", "generate", "-o", str(node), "-n", "1", "--resume", *PLAN],
        "overwrite": ["dataset", "generate", "-o", str(node), "-n", "1", "--force", *PLAN],
        "collect": ["collect", "--robot", "sim", "-o", str(node), "-n", "1", "--resume", *PLAN],
        "features": ["dataset", "features", str(node), "--no-progress"],
        "export": ["dataset", "export-features", str(node), "-o", str(tmp_path / "t.csv")],
        "export to": ["dataset", "export-features", str(small), "-o", str(node), "--force"],
        "prior from": ["prior", "build", str(node), "-o", str(tmp_path / "p.npz")],
        "prior to": ["prior", "build", str(small), "-o", str(node), "--force"],
        "inspect": ["prior", "inspect", str(node)],
    }
    for name, argv in commands.items():
        assert main(argv) == 1, name
        line = one_error_line(capsys)
        assert str(node) in line and ("not a regular file" in line or "directory" in line), (
            name,
            line,
        )
        assert "repair" not in line.split(":", 2)[-1], (name, line)
        assert what(node) == before, name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["node"]


@pytest.mark.parametrize("kind", KINDS)
def test_the_library_refuses_them_too(kind, tmp_path):
    node = make(kind, tmp_path / "node")
    before = what(node)
    for attempt in (
        lambda: DatasetReader(node),
        lambda: DatasetWriter(node, "a"),
        lambda: DatasetWriter(node, "w", overwrite=True),
        lambda: repair(node),
    ):
        with pytest.raises(DatasetError, match="not a regular file|directory"):
            attempt()
        assert what(node) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["node"]


def test_dev_null_itself(capsys):
    assert main(["dataset", "info", os.devnull]) == 1
    assert "is a character device, not a regular file" in one_error_line(capsys)


@pytest.mark.parametrize("side", [".crashed", ".repairing", ".creating", ".lock"])
def test_a_side_file_that_is_not_a_regular_file_is_never_replaced(small, tmp_path, side, capsys):
    data = tmp_path / "d.h5"
    data.write_bytes(small.read_bytes())
    node = make("fifo", tmp_path / f"d.h5{side}")
    argv = (
        ["dataset", "generate", "-o", str(data), "-n", "1", "--force", *PLAN]
        if side == ".creating"
        else ["dataset", "repair", str(data)]
    )
    assert main(argv) == 1
    line = one_error_line(capsys)
    assert f"d.h5{side}" in line and "not" in line
    assert stat.S_ISFIFO(os.lstat(node).st_mode)
    assert data.read_bytes() == small.read_bytes()


def test_an_output_directory_holding_a_fifo_named_as_a_result_is_refused(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    make("fifo", out / "summary.json")
    (out / "unrelated").mkdir()
    table = tmp_path / "t.csv"
    rows = [f"{o},p,{t},{k + 0.1 * t}" for k, o in enumerate("abcd") for t in range(3)]
    table.write_text("object,action,trial,force.0\n" + "\n".join(rows) + "\n")
    argv = ["learn", "--table", str(table), "--objects", "a,b"]
    assert main([*argv, "--prior-objects", "c,d", "-o", str(out)]) == 1
    assert "summary.json, a FIFO" in one_error_line(capsys)


# -- one writer per data set ---------------------------------------------------------------------
def aptkt(*argv: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "aptkt.cli", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def wait_for_recordings(path: Path, n: int, proc: subprocess.Popen, timeout: float = 120.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        if path.exists():
            try:
                with DatasetReader(path) as rd:
                    if len(rd) >= n:
                        return
            except DatasetError:
                pass  # (caught as it is created)
        time.sleep(0.2)
    raise AssertionError(f"{path}: no {n} recordings within {timeout} s")


#: A plan the first writer takes minutes over (it is stopped once the test is done with it).
LONG = ["-n", "300", "-j", "1", *PLAN]


def stop(proc: subprocess.Popen) -> None:
    """SIGTERM: the writer stops cleanly, keeping what it wrote (exit code 143)."""
    proc.terminate()
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err


@pytest.mark.slow
def test_a_second_writer_is_refused_naming_the_first(tmp_path):
    # The report: a second `generate --resume` 6 s after the first "repaired a crashed file
    # first (31 recordings kept)": it renamed the live file away under the running writer.
    data = tmp_path / "c0.h5"
    generate_argv = ["dataset", "generate", "-o", str(data), *LONG]
    first = aptkt(*generate_argv)
    wait_for_recordings(data, 2, first)
    rivals = {
        "resume": [*generate_argv, "--resume"],
        "overwrite": [*generate_argv, "--force"],
        "repair": ["dataset", "repair", str(data)],
        "features": ["dataset", "features", str(data), "--no-progress"],
        "collect": ["collect", "--robot", "sim", "-o", str(data), "-n", "6", "--resume", *PLAN],
    }
    for name, argv in rivals.items():
        assert first.poll() is None, "the first writer ended before its rivals came"
        proc = aptkt(*argv)
        out, err = proc.communicate(timeout=120)
        assert proc.returncode == 1, (name, out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in err, (name, err)
        assert f"is being written by process {first.pid} on {socket.gethostname()}" in err, err
        assert "dataset generate" in err  # the holder's command
    written = os.stat(data).st_ino
    stop(first)
    assert os.stat(data).st_ino == written  # the file it wrote was never replaced
    with DatasetReader(data) as rd:
        assert len(rd) >= 2 and not rd.damaged(full=True) and not rd.writer_died
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c0.h5"]  # no .crashed, no lock left


def test_info_names_the_live_writer(tmp_path):
    data = tmp_path / "live.h5"
    first = aptkt("dataset", "generate", "-o", str(data), *LONG)
    wait_for_recordings(data, 1, first)
    info = aptkt("dataset", "info", str(data))
    out, err = info.communicate(timeout=60)
    assert first.poll() is None, "the writer ended before info ran"
    assert info.returncode == 0, err
    assert f"being written now by process {first.pid}" in out
    assert "repair" not in out
    stop(first)


def test_a_lock_left_by_a_killed_writer_is_taken_over(tmp_path):
    data = tmp_path / "killed.h5"
    first = aptkt("dataset", "generate", "-o", str(data), *LONG)
    wait_for_recordings(data, 2, first)
    first.kill()
    first.wait()
    record = json.loads(lock_path(data).read_text())
    assert record["pid"] == first.pid  # left behind by the kill, naming the dead writer
    with WriterLock.acquire(data) as lock:
        assert lock.taken_over is not None and lock.taken_over["pid"] == first.pid
    resume = aptkt("dataset", "generate", "-o", str(data), "-n", "2", *PLAN, "--resume")
    out, err = resume.communicate(timeout=300)
    assert resume.returncode == 0, err
    with DatasetReader(data) as rd:
        assert {(o, a, t) for o in OBJECTS for a in ("P1", "S1") for t in (0, 1)} <= set(rd.keys())
    assert not lock_path(data).exists()


def test_one_process_cannot_hold_a_lock_twice(tmp_path):
    data = tmp_path / "x.h5"
    with WriterLock.acquire(data):
        with pytest.raises(DatasetError, match=f"being written by process {os.getpid()}"):
            WriterLock.acquire(data)
        with pytest.raises(DatasetError, match="being written"):
            DatasetWriter(data, "w")
    with DatasetWriter(data, "w"):
        assert lock_path(data).exists()
    assert not lock_path(data).exists()


RACER = """
import os, sys, time
from pathlib import Path
from aptkt.data.lock import WriterLock
from aptkt.errors import DatasetError

data, marker, rounds = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
held = 0
while held < rounds:
    try:
        lock = WriterLock.acquire(data)
    except DatasetError:
        continue
    # Two holders at once would both create the marker: O_EXCL fails for the second.
    fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    os.close(fd)
    time.sleep(0.0005)
    os.unlink(marker)
    lock.release()
    held += 1
"""


def test_racing_processes_never_hold_the_lock_together(tmp_path):
    # Each release removes the lock file while other processes open, lock and check it.
    racers = [
        subprocess.Popen(
            [sys.executable, "-c", RACER, str(tmp_path / "r.h5"), str(tmp_path / "m"), "150"],
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(4)
    ]
    for racer in racers:
        _, err = racer.communicate(timeout=300)
        assert racer.returncode == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["generate", "collect"])
def test_a_data_set_in_a_directory_not_made_yet_gets_its_directory(command, tmp_path, capsys):
    """As every output of aptkt (a prior, a report): the directories are made, and the
    refusal to write under a file stays one line."""
    out = tmp_path / "not" / "yet" / "d.h5"
    if command == "generate":
        argv = ["dataset", "generate", "-o", str(out), "--objects", "towel", "--actions", "P1"]
        argv += ["-n", "1", "-j", "1", "--no-progress"]
    else:
        argv = ["collect", "--robot", "sim", "--objects", "towel", "--actions", "P1", "-n", "1"]
        argv += ["-o", str(out)]
    assert main(argv) == 0
    with DatasetReader(out) as rd:
        assert len(rd) == 1
    (tmp_path / "afile").write_text("x")
    argv[argv.index(str(out))] = str(tmp_path / "afile" / "d.h5")
    capsys.readouterr()
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is a file" in err[0]
