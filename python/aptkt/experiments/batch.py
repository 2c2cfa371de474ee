"""Running a batch of experiment runs with resume: finished runs are read back from the
:class:`~aptkt.experiments.run_store.RunStore`, the others are computed (on an executor) and stored
as each one completes, so an interrupted batch loses at most the runs in flight."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aptkt.errors import InvalidStateError, UnknownNameError
from aptkt.experiments.executors import Executor
from aptkt.experiments.priors import PriorTask, build_prior
from aptkt.experiments.run_store import RunStore, run_key
from aptkt.experiments.runs import RunSpec, run_steps
from aptkt.progress import Progress

__all__ = ["BatchResult", "StoredSteps", "run_batch", "build_priors"]


class StoredSteps(Mapping[str, list[dict[str, Any]]]):
    """Run key → step rows, read from the store when asked for. A full-size reproduction's
    rows (every classifier's hyper-parameters at every step of 3,650 runs) take gigabytes as
    Python objects; read per figure, only the figures being analysed (one per worker) have
    their rows in memory."""

    def __init__(self, store: RunStore, keys: Sequence[str]) -> None:
        self._store = store
        self._keys = dict.fromkeys(keys)  # spec order, each run once, O(1) lookups

    def __getitem__(self, key: str) -> list[dict[str, Any]]:
        if key not in self._keys:
            raise UnknownNameError(key)
        rows = self._store.load(key)
        if rows is None:
            raise InvalidStateError(
                f"run {key}: its result file {self._store.path(key)} disappeared or was damaged "
                "after the batch stored or found it"
            )
        return rows

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)

    def __repr__(self) -> str:
        return f"StoredSteps({len(self)} runs)"

    def __contains__(self, key: object) -> bool:
        return key in self._keys


@dataclass
class BatchResult:
    """Step rows per run key (read from the store on access), how many runs were computed now
    vs read back, and the runs' own time summed (their steps' wall time in the workers)."""

    steps: StoredSteps
    computed: int
    reused: int
    run_seconds: float


def _bar(progress: bool, total: int, initial: int, desc: str) -> Progress:
    return Progress(total, "run", desc, initial=initial, enabled=progress)


def build_priors(tasks: Sequence[PriorTask], executor: Executor, *, progress: bool = True) -> None:
    """Build every distinct prior-knowledge file that does not exist yet."""

    todo = {t.key: t for t in tasks if not Path(t.path).exists()}
    if not todo:
        return
    bar = _bar(progress, len(todo), 0, "prior knowledge")
    try:
        for _ in executor.imap_unordered(build_prior, list(todo.values())):
            bar.update(1)
    finally:
        bar.close()


def run_batch(
    specs: Sequence[RunSpec],
    store: RunStore,
    executor: Executor,
    fingerprint: str,
    *,
    progress: bool = True,
    desc: str = "runs",
    task: Callable[[RunSpec], list[dict[str, Any]]] = run_steps,
) -> BatchResult:
    """Every spec's step rows; runs already in ``store`` are not recomputed, runs with equal
    keys are computed once. ``task`` is the function that performs one run (tests substitute
    it to count or interrupt)."""
    keys = [run_key(s, fingerprint) for s in specs]
    done: set[str] = set()
    todo: dict[str, RunSpec] = {}
    run_seconds = 0.0
    for key, spec in zip(keys, specs):
        if key in done or key in todo:
            continue
        stored = store.load(key)
        if stored is not None:
            done.add(key)
            run_seconds += _seconds(stored)
        else:
            todo[key] = spec
    reused = len(done)
    bar = _bar(progress, reused + len(todo), reused, desc)
    order = list(todo)
    # Each worker stores its own run (an absolute path: a cluster's workers have their own
    # working directories); the main process only counts, and checks that the file is there
    # for it too. Receiving, writing and reading back every run's rows made the main process
    # the serial part of a reproduction.
    stored_run = _StoredRun(str(store.directory.resolve()), task)
    try:
        for i, seconds in executor.imap_unordered(stored_run, [(k, todo[k]) for k in order]):
            key = order[i]
            if key not in store:
                raise InvalidStateError(
                    f"run {key}: a worker stored it, but {store.path(key)} is not there for this "
                    "process; with a cluster, the output directory must be on a file system the "
                    "workers share"
                )
            done.add(key)
            run_seconds += seconds
            bar.update(1)
    finally:
        bar.close()
    return BatchResult(
        StoredSteps(store, keys), computed=len(todo), reused=reused, run_seconds=run_seconds
    )


@dataclass(frozen=True)
class _StoredRun:
    """One run, performed and stored where it runs (a worker process, a cluster node sharing
    the output directory); returns the run's own seconds."""

    directory: str
    task: Callable[[RunSpec], list[dict[str, Any]]]

    def __call__(self, item: tuple[str, RunSpec]) -> float:
        key, spec = item
        rows = self.task(spec)
        RunStore(self.directory).save(key, spec, rows)
        return _seconds(rows)


def _seconds(rows: list[dict[str, Any]]) -> float:
    return sum(float(r.get("seconds") or 0) for r in rows)
