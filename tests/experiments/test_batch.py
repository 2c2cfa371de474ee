"""Resume after an interruption, local processes and a Dask cluster: all give the same results."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from aptkt.errors import WorkerDiedError
from aptkt.experiments.batch import build_priors, run_batch
from aptkt.experiments.executors import LocalExecutor, make_executor
from aptkt.experiments.figures import fig7, fig8
from aptkt.experiments.figures.base import Context
from aptkt.experiments.reproduce import _paper_numbers
from aptkt.experiments.run_store import RunStore, data_fingerprint
from aptkt.experiments.runs import run_steps
from aptkt.experiments.scale import Scale

THREAD_VARIABLES = [
    "RAYON_NUM_THREADS",
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
]


@pytest.fixture(scope="module")
def design(quick_data, tmp_path_factory):
    """A few of the quick Fig. 7 and Fig. 8 runs, with their prior knowledge built."""
    scale = Scale.quick()
    out = tmp_path_factory.mktemp("batch")
    fp = data_fingerprint(quick_data)
    ctx = Context(
        scale=scale,
        seed=0,
        data=str(quick_data),
        fingerprint=fp,
        output=out,
        index=_paper_numbers(scale.objects),
    )
    p7, p8 = fig7.plan(ctx), fig8.plan(ctx)
    build_priors(p7.priors, LocalExecutor(1), progress=False)
    specs = p7.specs[:4] + p8.specs[:2]
    return specs, fp, out, p7.priors


def canonical(steps):
    """Results as text, without the wall-clock column (NaN written as NaN, so it compares)."""
    return json.dumps(
        {
            k: [{c: v for c, v in r.items() if c != "seconds"} for r in rows]
            for k, rows in sorted(steps.items())
        },
        sort_keys=True,
    )


@pytest.fixture(scope="module")
def uninterrupted(design, tmp_path_factory):
    specs, fp, _, _ = design
    return run_batch(
        specs, RunStore(tmp_path_factory.mktemp("one-go")), LocalExecutor(1), fp, progress=False
    )


@pytest.mark.slow
def test_resume_after_interruption_equals_one_uninterrupted_run(design, uninterrupted, tmp_path):
    specs, fp, _, _ = design
    store = RunStore(tmp_path / "runs")
    done = []

    def interrupted_after_three(spec):
        if len(done) == 3:
            raise KeyboardInterrupt
        done.append(spec)
        return run_steps(spec)

    with pytest.raises(KeyboardInterrupt):
        run_batch(specs, store, LocalExecutor(1), fp, progress=False, task=interrupted_after_three)
    assert len(store.keys()) == 3  # every run finished before the interruption was kept

    again = []

    def counting(spec):
        again.append(spec)
        return run_steps(spec)

    resumed = run_batch(specs, store, LocalExecutor(1), fp, progress=False, task=counting)
    assert (resumed.reused, resumed.computed) == (3, len(specs) - 3)
    assert len(again) == len(specs) - 3 and not any(s in done for s in again)
    assert canonical(resumed.steps) == canonical(uninterrupted.steps)
    assert len(resumed.steps) == len(specs)


def test_batch_reads_rows_from_the_store_when_asked(design, uninterrupted, tmp_path):
    """The batch keeps keys, not rows (a full-size reproduction's rows take gigabytes): what it
    returns is what the store holds, read on access; a result file damaged afterwards is an
    error naming it, not a silently missing run."""
    specs, fp, _, _ = design
    store = RunStore(tmp_path / "runs")
    res = run_batch(specs, store, LocalExecutor(1), fp, progress=False)
    assert canonical(res.steps) == canonical(uninterrupted.steps)
    key = next(iter(res.steps))
    assert res.steps[key] == store.load(key)
    summed = sum(float(r["seconds"]) for k in res.steps for r in store.load(k))
    assert res.run_seconds == pytest.approx(summed)
    with pytest.raises(KeyError):
        res.steps["not-a-run"]
    store.path(key).write_text("{")
    with pytest.raises(RuntimeError, match=key):
        res.steps[key]


def test_local_processes_give_the_same_results(design, uninterrupted, tmp_path):
    specs, fp, _, _ = design
    executor = LocalExecutor(2)
    try:
        res = run_batch(specs, RunStore(tmp_path / "runs"), executor, fp, progress=False)
    finally:
        executor.close()
    assert res.computed == len(specs)
    assert canonical(res.steps) == canonical(uninterrupted.steps)


def test_dask_cluster_gives_the_same_results(design, uninterrupted, tmp_path):
    from dask.distributed import LocalCluster

    specs, fp, _, priors = design
    # Prior knowledge built on the cluster too, into a fresh directory.
    fresh = [type(t)(**{**t.to_dict(), "directory": str(tmp_path / "priors")}) for t in priors]
    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster:
        executor = make_executor(scheduler=cluster.scheduler_address)
        try:
            assert "Dask cluster" in executor.description
            build_priors(fresh, executor, progress=False)
            res = run_batch(specs, RunStore(tmp_path / "runs"), executor, fp, progress=False)
        finally:
            executor.close()
    assert all((tmp_path / "priors").joinpath(t.path.rsplit("/", 1)[1]).exists() for t in fresh)
    assert res.computed == len(specs)
    assert canonical(res.steps) == canonical(uninterrupted.steps)


def test_the_package_does_not_import_dask():
    code = (
        "import sys, aptkt.cli, aptkt.experiments.reproduce, aptkt.experiments.executors; "
        "sys.exit(any(m == 'dask' or m.startswith('dask.') for m in sys.modules))"
    )
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def _in_workers(executor: LocalExecutor, variables: list[str]) -> dict[str, str | None]:
    # os.getenv pickles by reference, so the spawned workers can run it (a test-module function
    # could not be imported there).
    try:
        return {variables[i]: value for i, value in executor.imap_unordered(os.getenv, variables)}
    finally:
        executor.close()


def test_local_workers_share_the_cores(monkeypatch):
    # Two workers on a 4-core machine get 2 threads each, not 4 (8 threads on 4 cores).
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr("os.cpu_count", lambda: 4)
    assert _in_workers(LocalExecutor(2), THREAD_VARIABLES) == dict.fromkeys(THREAD_VARIABLES, "2")


def test_a_thread_count_the_user_set_wins(monkeypatch):
    monkeypatch.setenv("RAYON_NUM_THREADS", "3")
    monkeypatch.setattr("os.cpu_count", lambda: 4)
    assert (
        _in_workers(LocalExecutor(2), ["RAYON_NUM_THREADS", "OMP_NUM_THREADS"])["RAYON_NUM_THREADS"]
        == "3"
    )


def test_a_worker_that_dies_is_a_typed_error_and_the_executor_recovers():
    executor = LocalExecutor(2)
    try:
        # os._exit pickles by reference, like os.getenv above: the worker ends on the spot.
        with pytest.raises(WorkerDiedError, match="worker process died"):
            list(executor.imap_unordered(os._exit, [7, 7]))
        assert dict(executor.imap_unordered(os.getenv, ["PATH", "HOME"])).keys() == {0, 1}
    finally:
        executor.close()
