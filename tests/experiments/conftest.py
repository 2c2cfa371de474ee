"""A quick reproduction of every figure, run once per test session (it simulates its own small
data set, ≈ 30 s on 2 cores); the other tests reuse its data set and prior knowledge, which they
only read. pytest-xdist's workers share it: the first to need it runs it while the others wait,
instead of each worker running it again on the same cores."""

from __future__ import annotations

import fcntl
import shutil

import pytest

from aptkt.cli import main


@pytest.fixture(scope="session")
def quick_run(tmp_path_factory, worker_id):
    # The workers' temporary directories share a parent; a run alone has only its own.
    shared = tmp_path_factory.getbasetemp()
    if worker_id != "master":
        shared = shared.parent
    out, done = shared / "reproduce-quick", shared / "reproduce-quick.done"
    with open(shared / "reproduce-quick.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not done.exists():
            shutil.rmtree(out, ignore_errors=True)  # a worker's attempt that failed
            argv = ["reproduce", "all", "--quick", "--output", str(out), "--jobs", "2"]
            assert main([*argv, "--no-progress"]) == 0
            done.touch()
    return out


@pytest.fixture(scope="session")
def quick_data(quick_run):
    (path,) = quick_run.glob("data-quick-seed0.h5")
    return path
