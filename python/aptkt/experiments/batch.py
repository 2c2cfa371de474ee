"""Running a batch of experiment runs with resume: finished runs are read back from the
:class:`~aptkt.experiments.run_store.RunStore`, the others are computed (on an executor) and stored
as each one completes, so an interrupted batch loses at most the runs in flight."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from aptkt.experiments.executors import Executor
from aptkt.experiments.priors import PriorTask, build_prior
from aptkt.experiments.run_store import RunStore, run_key
from aptkt.experiments.runs import RunSpec, run_steps

__all__ = ["BatchResult", "run_batch", "build_priors"]


@dataclass
class BatchResult:
    """Step rows per run key, and how many runs were computed now vs read back."""

    steps: dict[str, list[dict[str, Any]]]
    computed: int
    reused: int


def _bar(progress: bool, total: int, initial: int, desc: str):
    return tqdm(
        total=total, initial=initial, unit="run", desc=desc, disable=not progress, smoothing=0.05
    )


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
    steps: dict[str, list[dict[str, Any]]] = {}
    todo: dict[str, RunSpec] = {}
    for key, spec in zip(keys, specs):
        if key in steps or key in todo:
            continue
        stored = store.load(key)
        if stored is not None:
            steps[key] = stored
        else:
            todo[key] = spec
    reused = len(steps)
    bar = _bar(progress, reused + len(todo), reused, desc)
    order = list(todo)
    try:
        for i, rows in executor.imap_unordered(task, [todo[k] for k in order]):
            key = order[i]
            store.save(key, todo[key], rows)
            # Read back what was stored, so fresh and resumed results are the same values.
            stored = store.load(key)
            if stored is None:
                raise RuntimeError(
                    f"run {key}: its result file {store.path(key)} cannot be read back"
                )
            steps[key] = stored
            bar.update(1)
    finally:
        bar.close()
    return BatchResult(steps, computed=len(todo), reused=reused)
