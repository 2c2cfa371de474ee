"""Simulating workers start with one thread per pool: OpenBLAS's spinning threads cost as much
CPU as the simulation itself (aptkt.runtime.worker_start)."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os

from aptkt.runtime.worker_start import THREAD_POOL_VARIABLES, start_worker

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
