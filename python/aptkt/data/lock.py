"""One writer per data set, across processes: an advisory lock beside the file.

HDF5's own file lock does not serve: a writer in SWMR mode gives it up, so a second writer, a
repair or a ``--resume`` started while the first ran used to find the file "not closed by its
writer", repair it, and rename the live file away under the running writer. Every process
that writes a data set — appends, repairs, stores features — now holds ``<file>.lock`` for as
long as it writes, locked with ``flock``; the file records the holder (process id, host,
start, command) for the message that refuses the next one.

The kernel releases a ``flock`` when its holder ends however it ends (a kill, a crash, a power
cut's reboot), so a lock file left by a dead process is free: the next writer takes it over
and overwrites the record. The record alone never decides; it only names the holder.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import socket
import stat
import sys
import time
from pathlib import Path
from typing import Any

from aptkt.errors import DatasetError
from aptkt.files import not_a_regular_file, refuse_unless_regular

__all__ = ["LOCK_SUFFIX", "WriterLock", "lock_path", "holder"]

#: The suffix of a data set's lock file.
LOCK_SUFFIX = ".lock"
#: A holder's record is small; more is not a record of ours.
_RECORD_MAX_BYTES = 4096


def lock_path(path: str | Path) -> Path:
    path = Path(path)
    name = path.name
    if len(os.fsencode(name)) > 240:  # the suffix must not take the name past the limit
        name = name[:120]
    return path.with_name(name + LOCK_SUFFIX)


def _read_record(fd: int) -> dict[str, Any] | None:
    try:
        raw = os.pread(fd, _RECORD_MAX_BYTES, 0)
        record = json.loads(raw.decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return None
    return record if isinstance(record, dict) else None


def _alive(record: dict[str, Any]) -> bool | None:
    """Whether the recorded process runs (None: it ran on another host, or is not named)."""
    pid = record.get("pid")
    if record.get("host") != socket.gethostname() or not isinstance(pid, int) or pid <= 0:
        return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # (EPERM: it runs, as another user)
        return True
    return True


def describe(record: dict[str, Any] | None) -> str:
    """``process 4711 on lab-pc (since 2024-05-02 10:31:07: aptkt dataset generate ...)``."""
    if not record:
        return "another process (it has not recorded itself yet)"
    since = record.get("since")
    when = (
        time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(since))
        if isinstance(since, (int, float))
        else "?"
    )
    command = str(record.get("command") or "")[:200]
    text = f"process {str(record.get('pid'))[:20]} on {str(record.get('host'))[:100]} (since {when}"
    return text + (f": {command})" if command else ")")


def holder(path: str | Path) -> dict[str, Any] | None:
    """The record of the process writing ``path`` now, if its lock file names one that runs on
    this host (for ``dataset info``; a writer finds out by taking the lock)."""
    try:
        fd = os.open(lock_path(path), os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        record = _read_record(fd)
    finally:
        os.close(fd)
    return record if record is not None and _alive(record) else None


def _command() -> str:
    """What the holder runs, for the message: ``aptkt dataset generate -o ...``."""
    argv = sys.argv
    if argv and os.path.basename(argv[0]) in ("aptkt", "cli.py"):
        argv = ["aptkt", *argv[1:]]
    return " ".join(argv)[:500]


class WriterLock:
    """The lock of the data set ``path``, held from :meth:`acquire` until :meth:`release`.

    ``taken_over``: the record of a holder that had ended without releasing it (killed), whose
    lock file this one took over; None if the lock file was new."""

    def __init__(self, path: Path, fd: int, taken_over: dict[str, Any] | None):
        self.path = path
        self.file = lock_path(path)
        self._fd: int | None = fd
        self._pid = os.getpid()
        self.taken_over = taken_over

    @classmethod
    def acquire(cls, path: str | Path) -> WriterLock:
        """Take the lock of ``path`` or raise a :class:`~aptkt.errors.DatasetError` naming the
        process that holds it. Never waits: a writer runs for hours."""
        path = Path(path)
        refuse_unless_regular(path, DatasetError)
        file = lock_path(path)
        try:
            # A data set's directory is made as every output's is (a prior, a report).
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DatasetError(
                f"{path}: cannot create its directory {path.parent}: {exc.strerror or exc}"
            ) from None
        while True:
            kind = not_a_regular_file(file)
            if kind is not None:
                raise DatasetError(
                    f"{file}: is {kind}, not the lock file of {path.name}; aptkt writes only "
                    "regular files: remove or rename it"
                )
            try:
                fd = os.open(
                    file,
                    os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC,
                    0o644,
                )
            except OSError as exc:
                raise DatasetError(
                    f"{path}: cannot create its lock file {file}: {exc.strerror or exc}"
                ) from None
            if not stat.S_ISREG(os.fstat(fd).st_mode):  # (swapped in since the check above)
                os.close(fd)
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                record = _read_record(fd)
                os.close(fd)
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise DatasetError(
                        f"{path}: cannot lock {file}: {exc.strerror or exc}"
                    ) from None
                who = describe(record)
                if record is not None and _alive(record) is False:
                    who += ", which has ended; a process it started still holds the lock"
                raise DatasetError(
                    f"{path} is being written by {who}; one writer at a time: wait until it "
                    "ends, or stop it"
                ) from None
            # The file may have been removed (or replaced) by the holder releasing it between
            # our open and our lock: then the lock is on a name nobody else will open.
            try:
                same = os.stat(file, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
            except OSError:
                same = False
            if not same:
                os.close(fd)
                continue
            taken_over = _read_record(fd)
            record = {
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "since": time.time(),
                "command": _command(),
            }
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, json.dumps(record).encode(), 0)
            except OSError as exc:  # (a full disk: no lock rather than a lock naming no one)
                os.close(fd)
                raise DatasetError(
                    f"{path}: cannot write its lock file {file}: {exc.strerror or exc}"
                ) from None
            return cls(path, fd, taken_over)

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        """Give the lock up and remove its file (removed first, so that no process can lock
        the old file after this one let go: see :meth:`acquire`)."""
        fd, self._fd = self._fd, None
        if fd is None:
            return
        if os.getpid() == self._pid:  # (a forked child's copy: the parent still writes)
            try:
                os.unlink(self.file)
            except OSError:
                pass
        os.close(fd)

    def __enter__(self) -> WriterLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:
        try:
            self.release()
        except Exception:  # noqa: BLE001 - (at interpreter exit the kernel releases it anyway)
            pass
