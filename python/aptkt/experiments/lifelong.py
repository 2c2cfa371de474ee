"""The lifelong benchmark: a library that grows batch by batch, on any sensor's feature table.

In each of ``orders`` random orders of the table's objects, the first ``batch`` objects form
the library a lab starts with (built from the first half of their trials). Then the next
``batch`` objects arrive and are learned — with APTKT from the whole library, and with the
baseline from nothing, from the same pool (the first half of their trials) in the same order —
and the objects APTKT learned, with exactly the observations it made, are merged into the
library (:func:`~aptkt.learning.library.merge_priors`), which is refitted. And so on until the
objects run out (batches of ``batch``; the last, incomplete one is left out).

Measured per batch, paired by order: APTKT and the baseline at one observation per object and
at the end of the budget on the new objects' held-out trials (the second half); and the grown
library's own accuracy on the held-out trials of every object it holds, against a
nearest-class-mean rule on the same observations in the same metric (the library's).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import ConfigError, InvalidInputError
from aptkt.experiments.benchmark import _subset, each_result, parallel_map_of, split_trials
from aptkt.experiments.benchmark_report import announce_checks, checks_line
from aptkt.experiments.benchmark_settings import check_lifelong_objects
from aptkt.experiments.population import ObjectPopulation
from aptkt.experiments.schedule import schedule
from aptkt.files import write_json_atomically, write_text_atomically
from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge
from aptkt.learning.feature_table import FeatureTable
from aptkt.learning.library import merge_priors
from aptkt.learning.observations import Observations, ObservationTable

__all__ = [
    "LifelongSettings",
    "library_accuracy",
    "nearest_class_mean_accuracy",
    "run_order",
    "run_stream",
    "run_lifelong",
    "schedule",
]


@dataclass(frozen=True)
class LifelongSettings:
    """``batch``: the objects learned in each batch (and the starting library's size);
    ``stream``: instead of the table's objects, a stream of that many synthetic objects drawn
    from the population fitted on the table (:mod:`aptkt.experiments.population`), one stream
    per order, in batches that grow with the library from ``batch`` to
    :data:`~aptkt.experiments.schedule.LARGEST_BATCH` objects (the objects of a batch beyond the ``batch`` learned join the
    library with the first half of their trials)."""

    orders: int = 20
    batch: int = 5
    budget: int = 20
    seed: int = 0
    actions: tuple[str, ...] | None = None
    config: LearnerConfig = LearnerConfig()
    stream: int | None = None

    def __post_init__(self) -> None:
        if self.orders < 1:
            raise InvalidInputError(f"orders must be >= 1, got {self.orders}")
        if self.batch < 2:
            raise InvalidInputError(f"batch must be >= 2, got {self.batch}")
        if self.budget < 0:
            raise InvalidInputError(f"budget must be >= 0, got {self.budget}")
        if self.stream is not None and self.stream < 2 * self.batch:
            raise InvalidInputError(
                f"a stream needs at least {2 * self.batch} objects (a starting library and "
                f"one batch of {self.batch}), got {self.stream}"
            )


def library_accuracy(
    library: PriorKnowledge, test: ObservationTable, model: str = "identity"
) -> float:
    """Mean over actions of the library's accuracy on ``test`` (observations of its objects),
    in its feature space: by its generative model of its objects (``model="identity"``, the most
    probable known object of each observation) or by its one-vs-all GP classifier ("gp", only
    where the model holds every old object: within the limits of
    :mod:`aptkt.learning.locality`, or with the exact library model)."""
    accs = []
    for action, obs in test.items():
        ap = library[action]
        X = ap.pipeline.transform(obs)[0]
        if model == "gp":
            if not ap.covers_library:
                raise InvalidInputError(
                    f"action {action!r}: the library's GP classifier holds a sample of its "
                    "objects only (library_model 'local' beyond its limits)"
                )
            predicted = np.asarray(ap.model.predict(X)).astype(str)
        else:
            ident = ap.identity
            if ident is None:
                raise InvalidInputError(
                    f"action {action!r}: no object of the library was observed twice"
                )
            predicted = np.empty(len(X), dtype=object)
            for rows in _blocks(len(X), len(ident.objects_)):
                old, _ = ident.log_likelihoods_each(X[rows])
                predicted[rows] = np.asarray(ident.objects_)[np.argmax(old, axis=1)]
        accs.append(float(np.mean(predicted.astype(str) == obs.objects)))
    return float(np.mean(accs))


def nearest_class_mean_accuracy(library: PriorKnowledge, test: ObservationTable) -> float:
    """Mean over actions of the accuracy of the nearest class mean — each object's mean of the
    library's observations, in the library's feature space — on ``test``."""
    accs = []
    for action, obs in test.items():
        ap = library[action]
        X = ap.pipeline.transform(ap.observations)[0]
        objects = np.asarray(ap.observations.objects).astype(str)
        names, index = np.unique(objects, return_inverse=True)
        means = np.zeros((names.size, X.shape[1]))
        np.add.at(means, index, X)
        means /= np.bincount(index, minlength=names.size)[:, None]
        T = ap.pipeline.transform(obs)[0]
        nearest = np.empty(len(T), dtype=np.int64)
        for rows in _blocks(len(T), names.size):
            d = (means**2).sum(axis=1)[None, :] - 2.0 * T[rows] @ means.T
            nearest[rows] = d.argmin(axis=1)
        accs.append(float(np.mean(names[nearest] == obs.objects)))
    return float(np.mean(accs))


#: Observations are scored against the library's objects in blocks of about this many pairs.
BLOCK = 2_000_000


def _blocks(n: int, objects: int) -> list[slice]:
    step = max(1, BLOCK // max(objects, 1))
    return [slice(k, min(k + step, n)) for k in range(0, n, step)]


def _orders(objects: Sequence[str], s: LifelongSettings) -> list[list[str]]:
    check_lifelong_objects(objects, s.batch)
    rng = np.random.default_rng(s.seed)
    return [[str(o) for o in rng.permutation(list(objects))] for _ in range(s.orders)]


def run_order(
    index: int,
    order: Sequence[str],
    learn: ObservationTable,
    test: ObservationTable,
    s: LifelongSettings,
    sizes: Sequence[int] | None = None,
) -> list[dict[str, Any]]:
    """One order: the starting library, then batch after batch learned and merged. ``sizes``:
    the batches' sizes (default: ``s.batch`` each, while the order has objects); of each
    batch the first ``s.batch`` objects are learned, the others join the library with their
    learning trials. Rows: per batch, each method's curve (``method`` baseline/APTKT,
    ``step``, ``accuracy``) and the grown library's accuracy (``method`` library / NCM, step
    0), its size, the batch's CPU seconds and the process's memory after it. The features
    are transformed as the table's observations were computed
    (:func:`~aptkt.learning.pipeline.transforms_of`)."""
    actions = list(learn)
    seed = s.seed * 1_000_003 + index
    if sizes is None:
        sizes = [s.batch] * ((len(order) - s.batch) // s.batch)
    library_objects = list(order[: s.batch])
    library = PriorKnowledge.build(_subset(learn, library_objects), gp=s.config.gp, seed=seed)
    rows: list[dict[str, Any]] = []
    start = s.batch
    for b, size in enumerate(sizes, start=1):
        t0 = time.process_time()
        batch = list(order[start : start + size])
        start += size
        new, joining = batch[: s.batch], batch[s.batch :]
        pool, held = _subset(learn, new), _subset(test, new)
        tags = {
            "order": index,
            "batch": b,
            "library": len(library.objects),
            "new_objects": ",".join(new),
        }
        learned: dict[str, Any] = {}
        for method, transfer in (("baseline", "none"), ("APTKT", "paper")):
            cfg = replace(s.config, budget=s.budget, seed=seed + b, transfer=transfer)
            learner = APTKT(cfg, library if method == "APTKT" else None)
            run = learner.run(PoolEnvironment(pool, seed=seed + b), actions, new, test=held)
            rows += [
                {**tags, "method": method, "step": k, "accuracy": step.mean_accuracy}
                for k, step in enumerate(run.steps)
            ]
            if method == "APTKT":
                learned = {a: lrn.observations for a, lrn in learner.learners.items()}
        # What the robot observed of the new objects becomes a library of its own, then joins
        # (with the batch's other objects, built from their learning trials).
        if joining:
            learned = {
                a: Observations.concat([learned[a], _subset(learn, joining)[a]]) for a in actions
            }
        new_library = PriorKnowledge.build(learned, gp=library.gp_settings, seed=seed + b)
        library = merge_priors(
            [(f"library {b - 1}", library), (f"batch {b}", new_library)], seed=seed + b
        )
        library_objects += batch
        everything = _subset(test, library_objects)
        tags["library"] = len(library.objects)
        seconds = time.process_time() - t0
        cost = {"seconds": seconds, "memory_mb": _memory_mb()}
        rows.append(
            {
                **tags,
                "method": "library",
                "step": 0,
                "accuracy": library_accuracy(library, everything),
                **cost,
            }
        )
        if all(library[a].covers_library for a in actions):
            rows.append(
                {
                    **tags,
                    "method": "library GP",
                    "step": 0,
                    "accuracy": library_accuracy(library, everything, "gp"),
                }
            )
        rows.append(
            {
                **tags,
                "method": "NCM",
                "step": 0,
                "accuracy": nearest_class_mean_accuracy(library, everything),
            }
        )
    return rows


def _memory_mb() -> float:
    """This process's resident memory now (MB; its peak so far where /proc is not there)."""
    mebibyte = 2**20
    try:
        with open("/proc/self/statm") as fh:
            pages = int(fh.read().split()[1])
        import os

        return pages * os.sysconf("SC_PAGE_SIZE") / mebibyte
    except (OSError, ValueError, IndexError):
        import resource

        # ru_maxrss counts kibibytes on Linux.
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 2**10 / mebibyte


def run_stream(
    index: int, population: ObjectPopulation, trials: int, s: LifelongSettings
) -> list[dict[str, Any]]:
    """One order of a synthetic stream: ``s.stream`` objects of ``population`` (a stream of its
    own per order), each observed ``trials`` times by every action — the first half learned
    from, the second half held out — in batches growing with the library (:func:`schedule`)."""
    assert s.stream is not None
    drawn = population.draw(s.stream, trials, seed=s.seed * 1_000_003 + index, prefix=f"s{index}_")
    learn = {a: o.take(np.flatnonzero(o.trials < trials // 2)) for a, o in drawn.items()}
    test = {a: o.take(np.flatnonzero(o.trials >= trials // 2)) for a, o in drawn.items()}
    order = list(dict.fromkeys(next(iter(drawn.values())).objects.tolist()))
    return run_order(index, order, learn, test, s, schedule(s.stream, s.batch))


def stream_trials(table: FeatureTable, actions: Sequence[str]) -> int:
    """How many times each synthetic object is observed by each action: as often as the
    table's objects are (the median), and at least twice."""
    counts = [table.rows_of(o, a).size for a in actions for o in table.object_names]
    return max(2, int(np.median(counts)))


def _task(task: tuple[int, list[str], ObservationTable, ObservationTable, LifelongSettings]):
    return run_order(*task)


def _stream_task(task: tuple[int, ObjectPopulation, int, LifelongSettings]):
    return run_stream(*task)


def run_lifelong(
    table: FeatureTable,
    s: LifelongSettings,
    *,
    output: Path,
    jobs: int = 1,
    scheduler: Any = None,
    command: str = "",
    progress: bool = True,
    say: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Run the lifelong benchmark and write results.csv, summary.json, report.md and
    lifelong.png/.svg to ``output``. Returns the summary (its "checks" say which held)."""
    from aptkt import __version__
    from aptkt.experiments import lifelong_report as lr
    from aptkt.experiments.executors import make_executor
    from aptkt.experiments.plots import save_figure
    from aptkt.experiments.tables import write_csv
    from aptkt.progress import Progress

    actions = list(s.actions) if s.actions else table.action_names
    tasks: list[Any]
    fn: Callable[[Any], list[dict[str, Any]]]
    if s.stream is None:
        learn_rows, test_rows = split_trials(table, actions)
        learn = table.observations(actions, learn_rows)
        test = table.observations(actions, test_rows)
        orders = _orders(table.object_names, s)
        sizes = [s.batch] * ((len(table.object_names) - s.batch) // s.batch)
        tasks, fn = [(i, order, learn, test, s) for i, order in enumerate(orders)], _task
        what = f"{len(table.object_names)} objects"
        left = len(table.object_names) - s.batch * (1 + len(sizes))
        if left:
            # Batches are whole: the objects beyond them would never be learned. Say so, as a
            # table of 12 objects with --new 5 otherwise loses 2 of them without a word.
            what += (
                f" (each order leaves its last {left} out: {len(table.object_names)} is not "
                f"{s.batch} plus whole batches of {s.batch})"
            )
    else:
        population = ObjectPopulation.fit(table.observations(actions))
        trials = stream_trials(table, actions)
        sizes = schedule(s.stream, s.batch)
        tasks = [(i, population, trials, s) for i in range(s.orders)]
        fn = _stream_task
        what = (
            f"a stream of {s.stream} synthetic objects drawn from the population fitted on its "
            f"{len(table.object_names)} objects ({trials} trials each)"
        )
    executor = make_executor(jobs, scheduler)
    batches = (
        f"{len(sizes)} batch(es) of {s.batch}"
        if len(set(sizes)) <= 1
        else f"{len(sizes)} batches of {min(sizes)} to {max(sizes)} objects, {s.batch} learned each"
    )
    say(
        f"{table.path}: {what}, action(s) {', '.join(actions)}; {s.orders} orders: a library "
        f"of {s.batch}, then {batches} and merged, budget {s.budget}, on {executor.description}"
    )
    t0 = time.perf_counter()
    bar = Progress(s.orders, "order", "lifelong", enabled=progress)
    rows: list[dict[str, Any]] = []
    try:
        for _, r in each_result(fn, tasks, parallel_map_of(executor, jobs, scheduler)):
            rows += r
            bar.update(1)
    finally:
        executor.close()
        bar.close()
    seconds = time.perf_counter() - t0
    rows.sort(key=lambda r: (r["order"], r["batch"], r["method"], r["step"]))
    output.mkdir(parents=True, exist_ok=True)
    write_csv(output / "results.csv", rows)
    c = lr.tables(rows)
    found = lr.checks(c)
    head = {
        "table": str(table.path),
        "command": command,
        "software_version": __version__,
        "seconds": seconds,
        "jobs": jobs if scheduler is None else executor.description,
        "date": time.strftime("%Y-%m-%d"),
        "objects": len(table.object_names) if s.stream is None else s.stream,
        "stream": s.stream,
        "actions": actions,
        "orders": s.orders,
        "batch": s.batch,
        "batch_sizes": sizes,
        "budget": s.budget,
    }
    save_figure(lr.plot(c), output / "lifelong")
    summary = {
        **head,
        "learner": s.config.to_dict(),
        "results": lr.summary(c),
        "checks": [k.as_dict() for k in found],
    }
    write_json_atomically(output / "summary.json", summary, ConfigError)
    write_text_atomically(output / "report.md", lr.report_markdown(c, head, found), ConfigError)
    announce_checks(found, say)
    say(
        f"{checks_line(found)}; done in {seconds:.0f} s: "
        f"{output / 'report.md'}, {output / 'lifelong.png'}, {output / 'results.csv'}"
    )
    return summary
