"""The start of a spawned worker process, in a module that imports no numpy, and the pool that
an interruption ends at once (:class:`WorkerPool`).

OpenBLAS starts its thread pool when numpy is imported, and its threads spin for a while after
every call. A simulating worker calls BLAS only for small eigen-decompositions (the thermal
networks, 30–40 nodes), where extra threads cannot help, but their spinning cost as much CPU as
the simulation itself when two workers shared two cores (106 against 50 CPU-ms per trial).
So the thread-pool sizes are set in the environment first, before anything imports numpy (a
value the user set wins), and BLAS is limited to one thread again once it is loaded, in case
the parent's main module had numpy imported already (a spawned worker imports it too).
"""

from __future__ import annotations

import concurrent.futures as cf
import importlib
import multiprocessing
import os
import threading
import time
from collections.abc import Callable
from typing import Any

__all__ = [
    "SPAWN",
    "THREAD_POOL_VARIABLES",
    "WorkerPool",
    "exit_with_parent",
    "limit_thread_pools",
    "start_worker",
]

# Workers are spawned, never forked: a fork copies the parent's thread pools (rayon in the
# compiled core) without their threads, and the first parallel call in the child then hangs.
SPAWN = multiprocessing.get_context("spawn")

#: Seconds a terminated worker has to end before it is killed.
TERMINATE_WAIT_S = 5.0

#: Seconds between two looks at whether the process that started this worker still lives.
PARENT_CHECK_S = 0.5

#: Thread pools a worker may start: the compiled core's (rayon) and the BLAS libraries'.
THREAD_POOL_VARIABLES = (
    "RAYON_NUM_THREADS",
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
)


def limit_thread_pools(threads: int) -> None:
    """Set every thread pool's size to ``threads`` unless the user set it (effective only
    before the pools start, i.e. before numpy or the core's parallel code is first used)."""
    for name in THREAD_POOL_VARIABLES:
        os.environ.setdefault(name, str(threads))


def exit_with_parent() -> None:
    """End this worker when the process that started it dies. A pool's workers wait for work
    on a pipe that a SIGKILLed parent leaves open among them, so they would otherwise live on
    (measured: a killed ``dataset generate -j 2`` left its workers running for an hour).

    The parent is the process that started this one, as multiprocessing recorded it: if it
    died while this worker was still starting, ``os.getppid()`` already names whoever adopted
    the orphan, and watching that one would never end (seen: workers of a generator killed
    within its first second, left waiting for 25 minutes)."""
    started_by = multiprocessing.parent_process()
    parent = (
        started_by.pid if started_by is not None and started_by.pid is not None else os.getppid()
    )

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_S)
        os._exit(1)  # (nothing of a worker's is lost: results live only once the parent has them)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def start_worker(target: str, *args: Any) -> None:
    """Initializer of a simulating worker: one thread per pool, then ``target``
    (``"module:function"``, imported only now) called with ``args``."""
    exit_with_parent()
    limit_thread_pools(1)
    # Imported here, after the limits: importing the target is what loads numpy and BLAS.
    from threadpoolctl import threadpool_limits

    module, _, name = target.partition(":")
    init = getattr(importlib.import_module(module), name)
    threadpool_limits(1, user_api="blas")  # for the rest of this worker's life
    init(*args)


class WorkerPool:
    """A pool of ``jobs`` spawned worker processes (``pool``, a ``ProcessPoolExecutor``) that
    :meth:`end_now` ends at once: on an interruption its tasks are not waited for.

    A SIGTERM (``kill``, a scheduler's stop) reaches only aptkt's own process: the workers run
    on, and leaving the pool the usual way waits for every task they hold, minutes at full
    scale, for results nobody keeps (a benchmark's run, a chunk of simulated trials). And a
    signal that lands while the pool starts a worker can leave one it never registered (its
    start interrupted half-way), which no shutdown ends: a ``dataset generate`` signalled in
    its first second once took 40 s to say it was terminated, and longer to exit. So
    :meth:`end_now` cancels what has not started and terminates every child process started
    since the pool was made, registered or not."""

    def __init__(
        self,
        jobs: int,
        initializer: Callable[..., object] | None = None,
        initargs: tuple[Any, ...] = (),
    ) -> None:
        self._before = set(multiprocessing.active_children())
        self.pool = cf.ProcessPoolExecutor(
            max_workers=jobs, mp_context=SPAWN, initializer=initializer, initargs=initargs
        )

    def close(self) -> None:
        """Wait for the tasks submitted, then end the workers."""
        self.pool.shutdown(wait=True)

    def end_now(self) -> None:
        self.pool.shutdown(wait=False, cancel_futures=True)
        mine = [c for c in multiprocessing.active_children() if c not in self._before]
        for child in mine:
            child.terminate()
        for child in mine:
            child.join(TERMINATE_WAIT_S)
            if child.is_alive():
                child.kill()
                child.join()
