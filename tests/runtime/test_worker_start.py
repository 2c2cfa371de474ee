"""Simulating workers start with one thread per pool: OpenBLAS's spinning threads cost as much
CPU as the simulation itself; and an interrupted pool ends its workers at once, those it never
registered too (aptkt.runtime.worker_start)."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import time

from aptkt.experiments.executors import LocalExecutor
from aptkt.runtime.worker_start import SPAWN, THREAD_POOL_VARIABLES, WorkerPool, start_worker

_SEEN: object = None


def _init(value: object) -> None:
    global _SEEN
    _SEEN = value


def _report(_: object) -> tuple[list[int], dict[str, str | None], object]:
    import numpy as np  # loads BLAS in the worker, as the simulation does
    from threadpoolctl import threadpool_info

    np.linalg.eigh(np.eye(3))
    blas = [int(i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"]
    return blas, {v: os.environ.get(v) for v in THREAD_POOL_VARIABLES}, _SEEN


def test_a_worker_runs_one_blas_thread_and_its_initializer():
    with cf.ProcessPoolExecutor(
        1,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=start_worker,
        initargs=(f"{__name__}:_init", 7),
    ) as pool:
        blas, env, seen = pool.submit(_report, None).result(timeout=120)
    assert seen == 7  # the target ran, with its arguments
    assert blas and all(n == 1 for n in blas)
    for name, value in env.items():  # a value the user set wins
        assert value == os.environ.get(name, "1")


def _new_children(before: set) -> list:
    return [c for c in multiprocessing.active_children() if c not in before]


def test_an_interrupted_batch_ends_its_workers_without_waiting_for_their_tasks():
    """A SIGTERM reaches only aptkt's process: the workers would run their tasks on (minutes
    at full scale) while the command waited for results nobody keeps."""
    before = set(multiprocessing.active_children())
    executor = LocalExecutor(2)
    results = executor.imap_unordered(time.sleep, [0.0, 600.0, 600.0])
    assert next(results)[1] is None  # the first task's result; two workers hold a long task
    results.close()  # what an interruption in the caller's loop does to the generator
    assert _new_children(before) == []
    executor.close()


def test_a_finished_batch_keeps_its_workers_for_the_next():
    before = set(multiprocessing.active_children())
    executor = LocalExecutor(2)
    try:
        assert sorted(executor.imap_unordered(abs, [-1, -2, -3])) == [(0, 1), (1, 2), (2, 3)]
        workers = _new_children(before)
        assert workers and all(w.is_alive() for w in workers)
        assert sorted(executor.imap_unordered(abs, [-4])) == [(0, 4)]
    finally:
        executor.close()
    assert _new_children(before) == []


def test_ending_a_pool_ends_a_worker_it_never_registered():
    """A signal while the pool starts a worker can leave one started and not registered; no
    shutdown of the pool would end it. Stood in for here by a process started beside the pool."""
    before = set(multiprocessing.active_children())
    workers = WorkerPool(1)
    assert workers.pool.submit(abs, -1).result() == 1
    stray = SPAWN.Process(target=time.sleep, args=(600.0,), daemon=True)
    stray.start()
    workers.end_now()
    assert not stray.is_alive()
    assert _new_children(before) == []
