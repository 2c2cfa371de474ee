"""Learning runs as data: a :class:`RunSpec` says everything one run needs (all of it plain,
JSON-able values and file paths, so runs can go to other processes or machines), and
:func:`execute` performs it and returns plain result rows."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from typing import Any

from aptkt.experiments.executors import Executor, LocalExecutor
from aptkt.experiments.stress import learner_config_from_dict
from aptkt.learning import APTKT, LearnerConfig, LearningRun, PoolEnvironment, PriorKnowledge
from aptkt.learning.dataset import load_observations
from aptkt.learning.transfer_summary import final_decisions

__all__ = ["RunSpec", "execute", "flatten", "label", "run_many", "run_steps", "step_rows"]


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
        d["config"] = learner_config_from_dict(d["config"])
        for key in ("actions", "new_objects", "pool_trials", "test_trials"):
            d[key] = tuple(d[key])
        return cls(**d)


# Workers keep the tables of the runs they did: a figure's runs share a few of them.
@lru_cache(maxsize=64)
def _table(data: str, objects: tuple[str, ...], trials: tuple[int, ...], actions: tuple[str, ...]):
    return load_observations(data, actions=actions, objects=objects, trials=trials)


@lru_cache(maxsize=8)
def _prior(path: str) -> PriorKnowledge:
    return PriorKnowledge.load(path)


def run_steps(spec: RunSpec) -> list[dict[str, Any]]:
    """Perform one run; one row per step, without the spec's labels (method, tags).

    Besides the step record, each row counts the transfer decisions made at that step
    (``decisions``: every action's new objects at step 0, the updated action's afterwards),
    how many of them transferred a prior object (``transfers``), how many sources they
    transferred in all (``sources``)
    and the mean λ over those sources (``mean_lambda``, NaN without a transfer); and how many
    models were fitted at that step (``updates``) and how many of them in the prior's feature
    space (``prior_space``; the others in the new objects' own or the pooled space).
    """
    pool = _table(spec.data, spec.new_objects, spec.pool_trials, spec.actions)
    test = _table(spec.data, spec.new_objects, spec.test_trials, spec.actions)
    prior = _prior(spec.prior) if spec.prior else None
    learner = APTKT(spec.config, prior)
    run = learner.run(
        PoolEnvironment(pool, seed=spec.pool_seed), spec.actions, spec.new_objects, test
    )
    return step_rows(run, learner, spec.new_objects)


def step_rows(
    run: LearningRun, learner: APTKT | None = None, objects: Sequence[str] = ()
) -> list[dict[str, Any]]:
    """One row per step of a finished run, with the transfer counts of :func:`run_steps`; with
    the ``learner`` that made it, the last row has the final models' confusion over
    ``objects`` and the transfer decisions in force at the end (``final_transfer``: action ->
    new object -> decision)."""
    rows = []
    for step in run.steps:
        row = step.as_row()
        decisions = [v for d in step.transfer.values() for v in d.values()]
        lambdas = [lam for v in decisions for lam in v["sources"].values()]
        row["decisions"] = len(decisions)
        row["transfers"] = sum(1 for v in decisions if v["sources"])
        row["sources"] = len(lambdas)
        row["mean_lambda"] = sum(lambdas) / len(lambdas) if lambdas else float("nan")
        row["updates"] = len(step.feature_space)
        row["prior_space"] = sum(1 for v in step.feature_space.values() if v["space"] == "prior")
        rows.append(row)
    if rows and learner is not None:
        rows[-1]["confusion"] = final_confusion(learner, objects)
        rows[-1]["final_transfer"] = final_decisions(run.steps)
    return rows


def final_confusion(learner: APTKT, objects: Sequence[str]) -> list[list[int]]:
    """Test observations of each object (rows, in ``objects`` order) by the object the final
    models predict (columns), counted over every action's model on its own test observations."""
    pos = {o: i for i, o in enumerate(objects)}
    counts = [[0] * len(objects) for _ in objects]
    for action_learner in learner.learners.values():
        if action_learner.test_posteriors is None:
            continue
        model = action_learner.model
        assert model is not None  # it has test posteriors
        classes = [str(c) for c in model.classes_]
        predicted = [classes[k] for k in action_learner.test_posteriors.argmax(axis=1)]
        for truth, guess in zip(action_learner.test_objects, predicted):
            counts[pos[str(truth)]][pos[guess]] += 1
    return counts


def label(spec: RunSpec, steps: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Step rows labelled with the spec's method and tags."""
    return [{"method": spec.method, **spec.tags, **row} for row in steps]


def execute(spec: RunSpec) -> list[dict[str, Any]]:
    """Perform one run; one row per step with the spec's method and tags."""
    return label(spec, run_steps(spec))


def run_many(
    specs: Sequence[RunSpec],
    *,
    jobs: int | None = None,
    progress: Callable[[int], None] | None = None,
    executor: Executor | None = None,
) -> list[list[dict[str, Any]]]:
    """Execute runs on local processes, or on ``executor`` (kept open), results in the order
    of ``specs``."""

    results: list[list[dict[str, Any]] | None] = [None] * len(specs)
    own = executor is None
    runner: Executor = LocalExecutor(jobs) if executor is None else executor
    try:
        for i, rows in runner.imap_unordered(execute, list(specs)):
            results[i] = rows
            if progress:
                progress(1)
    finally:
        if own:
            runner.close()
    return [r for r in results if r is not None]


def flatten(results: Iterable[list[dict[str, Any]]]) -> list[dict[str, Any]]:
    return [row for rows in results for row in rows]
