"""Where experiment tasks run: local processes (default) or a Dask distributed cluster.

Both hand back results as they complete, as ``(index, result)`` pairs, so the caller can count
(or store) each one at once. Tasks are top-level functions of plain data (run specs,
prior-building tasks); with Dask, the data set and the output directory must be on a file system the workers
share (their paths travel inside the tasks).
"""

from __future__ import annotations

import base64
import concurrent.futures as cf
import os
import socket
from collections.abc import Callable, Iterator, Sequence
from typing import Any, Protocol

from aptkt.errors import ConfigError, WorkerDiedError
from aptkt.runtime.worker_start import WorkerPool, exit_with_parent, limit_thread_pools

__all__ = ["Executor", "LocalExecutor", "DaskExecutor", "make_executor", "check_scheduler"]

#: Seconds a scheduler has to greet a new connection. Dask's scheduler sends its handshake the
#: moment it accepts one (milliseconds); something else at the address (a web server, a proxy)
#: waits for a request, and Dask's client would wait, retry and misread its answer.
SCHEDULER_GREETING_SECONDS = 10.0
#: A Dask handshake is a few dozen bytes (its compression, Python version, pickle protocol).
_GREETING_MAX_BYTES = 1 << 16
#: An HTTP status line ("HTTP/1.1 101 Switching Protocols") is read within this many bytes.
_STATUS_LINE_MAX_BYTES = 1 << 12


def _share_cores(threads: int) -> None:
    """Worker initializer: each of ``jobs`` processes gets its share of the cores, so that
    ``jobs`` workers, each fitting its one-vs-all classifiers in parallel, do not run
    ``jobs × cores`` threads on ``cores`` cores. Runs before the first task, i.e. before any
    thread pool exists; a value the user set in the environment wins. Like every worker of
    aptkt's, it ends when the process that started it dies."""
    exit_with_parent()
    limit_thread_pools(threads)


class Executor(Protocol):
    description: str

    def imap_unordered(
        self, fn: Callable[[Any], Any], items: Sequence[Any]
    ) -> Iterator[tuple[int, Any]]:
        """Apply ``fn`` to every item; yield ``(index, result)`` in completion order."""
        ...

    def close(self) -> None: ...


class LocalExecutor:
    """``jobs`` spawned worker processes (``jobs == 1``: in this process, one task at a time).

    The worker pool lives as long as the executor, so workers keep their caches (loaded
    observation tables, prior knowledge) from one batch of tasks to the next.
    """

    def __init__(self, jobs: int | None = None) -> None:
        self.jobs = int(jobs or os.cpu_count() or 1)
        if self.jobs < 1:
            raise ConfigError(f"jobs must be >= 1, got {jobs}")
        self.description = f"{self.jobs} local process(es)"
        self._workers: WorkerPool | None = None

    def imap_unordered(
        self, fn: Callable[[Any], Any], items: Sequence[Any]
    ) -> Iterator[tuple[int, Any]]:
        if self.jobs == 1 or len(items) <= 1:
            # The tasks' numpy calls are small (a PCA of a few hundred rows per update), where
            # BLAS threads cannot help but spin after every call, as in the spawned workers
            # (runtime/worker_start.py); the core's own threads are not limited.
            from threadpoolctl import threadpool_limits

            with threadpool_limits(1, user_api="blas"):
                for i, item in enumerate(items):
                    yield i, fn(item)
            return
        if self._workers is None:
            threads = max(1, (os.cpu_count() or 1) // self.jobs)
            self._workers = WorkerPool(self.jobs, initializer=_share_cores, initargs=(threads,))
        workers = self._workers
        finished = False
        try:
            futures = {workers.pool.submit(fn, item): i for i, item in enumerate(items)}
            for fut in cf.as_completed(futures):
                try:
                    result = fut.result()
                except cf.process.BrokenProcessPool as exc:
                    raise WorkerDiedError(
                        "a worker process died abruptly (killed, out of memory or crashed); "
                        "finished runs are kept: run the same command again to resume"
                    ) from exc
                yield futures[fut], result
            finished = True
        finally:
            if not finished:
                # Interrupted, a task failed or a worker died: the tasks still held would give
                # results nobody keeps. The next batch, if any, starts a new pool.
                workers.end_now()
                self._workers = None

    def close(self) -> None:
        if self._workers is not None:
            self._workers.close()
            self._workers = None


def _receive(sock: socket.socket, n: int, address: str) -> bytes:
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        if not chunk:
            raise ConfigError(
                f"--scheduler {address}: closed the connection without the greeting a Dask "
                "scheduler sends (is it another service?)"
            )
        data += chunk
    return data


def _tcp_greeting(sock: socket.socket, address: str) -> None:
    """A Dask tcp listener speaks first: a length, then a frame naming its compression, Python
    and pickle protocol."""
    length = int.from_bytes(_receive(sock, 8, address), "little")
    if not 0 < length <= _GREETING_MAX_BYTES:
        raise ConfigError(
            f"--scheduler {address}: answers, but not as a Dask scheduler does (its "
            "first bytes are not a Dask handshake; is it another service?)"
        )
    if b"pickle-protocol" not in _receive(sock, length, address):
        raise ConfigError(
            f"--scheduler {address}: answers, but not with a Dask scheduler's handshake (is it "
            "another service?)"
        )


def _websocket_upgrade(sock: socket.socket, host: str, port: str, address: str) -> None:
    """A Dask ws listener is a WebSocket server at ``/``: asked to upgrade, it answers 101
    (Switching Protocols); a web server answers with a page or an error, which Dask's client
    would report as a traceback of its web library."""
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        (
            f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    status = b""
    while b"\r\n" not in status and len(status) < _STATUS_LINE_MAX_BYTES:
        chunk = sock.recv(_STATUS_LINE_MAX_BYTES)
        if not chunk:
            break
        status += chunk
    words = status.split(b"\r\n", 1)[0].split()
    if len(words) < 2 or not words[0].startswith(b"HTTP/") or words[1] != b"101":
        raise ConfigError(
            f"--scheduler {address}: answers, but not as a Dask scheduler does (no WebSocket "
            "upgrade; is it another service?)"
        )


def check_scheduler(address: str, seconds: float | None = None) -> None:
    """That a ``tcp://`` (or bare ``host:port``) or ``ws://`` address answers as a Dask
    scheduler does: over tcp it greets a new connection at once with a small handshake, over
    ws it accepts a WebSocket upgrade. A web server, a proxy or a silent service is a
    :class:`ConfigError` within ``seconds``, before Dask's client reads its bytes as lengths to
    allocate or raises from its web library; so is an address where nothing listens, at once.
    Other transports (``tls://``, ``wss://``, ``inproc://``...) are left to Dask."""
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    host, colon, port = rest.rstrip("/").rpartition(":")
    if scheme not in ("tcp", "ws") or not colon or not port.isdigit():
        return  # Dask's own parse names what is wrong with the address
    wait = SCHEDULER_GREETING_SECONDS if seconds is None else seconds
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=wait) as sock:
            sock.settimeout(wait)
            if scheme == "tcp":
                _tcp_greeting(sock, address)
            else:
                _websocket_upgrade(sock, host, port, address)
    except TimeoutError:
        raise ConfigError(
            f"--scheduler {address}: answered nothing within {wait:g} s; a Dask scheduler "
            "answers at once (is it another service?)"
        ) from None
    except OSError as exc:
        raise ConfigError(
            f"cannot reach the Dask scheduler at {address!r}: {exc.strerror or exc}"
        ) from None


class DaskExecutor:
    """Tasks on a Dask distributed cluster reached at ``address`` (``tcp://host:8786``, or an
    existing :class:`dask.distributed.Client` for tests and notebooks)."""

    def __init__(self, address: Any) -> None:
        try:
            from dask.distributed import Client
        except ImportError as exc:  # dask is an optional dependency
            raise ConfigError(
                "--scheduler needs dask[distributed]: pip install 'aptkt[dask]'"
            ) from exc
        if isinstance(address, Client):
            self.client, self._own = address, False
        else:
            if isinstance(address, str):
                check_scheduler(address)
            try:
                self.client, self._own = Client(address, timeout="20s"), True
            except ValueError as exc:  # dask's parse of the address
                raise ConfigError(
                    f"--scheduler {address!r} is not a scheduler address (e.g. "
                    f"tcp://host:8786): {exc}"
                ) from None
            except (OSError, TimeoutError) as exc:
                raise ConfigError(f"cannot reach the Dask scheduler at {address!r}: {exc}") from exc
            except Exception as exc:  # noqa: BLE001 - whatever Dask's transports raise: unusable
                raise ConfigError(
                    f"cannot use the Dask scheduler at {address!r}: {type(exc).__name__}: {exc}"
                ) from exc
        workers = len(self.client.scheduler_info().get("workers", {}))
        where = getattr(self.client.scheduler, "address", address)
        self.description = f"Dask cluster at {where} ({workers} worker(s))"

    def imap_unordered(
        self, fn: Callable[[Any], Any], items: Sequence[Any]
    ) -> Iterator[tuple[int, Any]]:
        from dask.distributed import as_completed  # optional dependency: the dask extra

        if not items:
            return
        futures = [self.client.submit(fn, item, pure=False) for item in items]
        index = {f.key: i for i, f in enumerate(futures)}
        try:
            for fut in as_completed(futures):
                yield index[fut.key], fut.result()
        finally:
            self.client.cancel([f for f in futures if not f.done()])

    def close(self) -> None:
        if self._own:
            self.client.close()


def make_executor(jobs: int | None = None, scheduler: Any = None) -> Executor:
    """A Dask executor if ``scheduler`` is given, else local processes."""
    if scheduler is not None:
        return DaskExecutor(scheduler)
    return LocalExecutor(jobs)
