"""Learning runs as data: a :class:`RunSpec` says everything one run needs (all of it plain,
JSON-able values and file paths, so runs can go to other processes or machines), and
:func:`execute` performs it and returns plain result rows."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from typing import Any

from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge
from aptkt.learning.dataset import load_observations

# Workers are spawned, never forked: a fork copies the parent's thread pools (rayon in the
# compiled core) without their threads, and the first parallel call in the child then hangs.
_SPAWN = multiprocessing.get_context("spawn")

__all__ = ["RunSpec", "execute", "run_many"]


@dataclass(frozen=True)
class RunSpec:
    """One learning run on pre-recorded data (the paper's offline protocol).

    ``data`` is an HDF5 data set with stored features; the new objects' observations with trial
    numbers in ``pool_trials`` form the pool the learner draws from, those in ``test_trials``
    the test set. ``prior`` is a saved :class:`PriorKnowledge` (None for a baseline without
    any prior feature space).
    """

    method: str
    config: LearnerConfig
    data: str
    actions: tuple[str, ...]
    new_objects: tuple[str, ...]
    pool_trials: tuple[int, ...]
    test_trials: tuple[int, ...]
    prior: str | None = None
    pool_seed: int = 0
    tags: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["config"] = self.config.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RunSpec:
        d = dict(d)
        d["config"] = LearnerConfig.from_dict(d["config"])
        for key in ("actions", "new_objects", "pool_trials", "test_trials"):
            d[key] = tuple(d[key])
        return cls(**d)


@lru_cache(maxsize=8)
def _table(data: str, objects: tuple[str, ...], trials: tuple[int, ...], actions: tuple[str, ...]):
    return load_observations(data, actions=actions, objects=objects, trials=trials)


@lru_cache(maxsize=8)
def _prior(path: str) -> PriorKnowledge:
    return PriorKnowledge.load(path)


def execute(spec: RunSpec) -> list[dict[str, Any]]:
    """Perform one run; one row per step with the spec's method and tags."""
    pool = _table(spec.data, spec.new_objects, spec.pool_trials, spec.actions)
    test = _table(spec.data, spec.new_objects, spec.test_trials, spec.actions)
    prior = _prior(spec.prior) if spec.prior else None
    learner = APTKT(spec.config, prior)
    run = learner.run(PoolEnvironment(pool, seed=spec.pool_seed), spec.actions, spec.new_objects, test)
    rows = []
    for step in run.steps:
        row = {"method": spec.method, **spec.tags, **step.as_row()}
        row["transfers"] = sum(1 for d in step.transfer.values() for v in d.values() if v["source"])
        rows.append(row)
    return rows


def run_many(
    specs: Sequence[RunSpec],
    *,
    jobs: int | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[list[dict[str, Any]]]:
    """Execute runs on local processes (results in the order of ``specs``)."""
    jobs = jobs or os.cpu_count() or 1
    if jobs <= 1 or len(specs) <= 1:
        out = []
        for spec in specs:
            out.append(execute(spec))
            if progress:
                progress(1)
        return out
    results: list[list[dict[str, Any]] | None] = [None] * len(specs)
    with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=_SPAWN) as pool:
        futures = {pool.submit(execute, s): i for i, s in enumerate(specs)}
        for fut in cf.as_completed(futures):
            results[futures[fut]] = fut.result()
            if progress:
                progress(1)
    return [r for r in results if r is not None]


def flatten(results: Iterable[list[dict[str, Any]]]) -> list[dict[str, Any]]:
    return [row for rows in results for row in rows]
