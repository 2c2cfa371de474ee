"""The real-data benchmark: APTKT against its baseline on any sensor's feature table.

Protocol (the paper's Fig. 7, 9 and 11 on recorded data): each of ``groups`` draws
``new_objects`` new objects from the table's objects, and from the others, for every library
size in ``libraries``, that many prior objects three ways — at random, the most similar and the
least similar to the new ones (:func:`prior_choices`). A group's libraries grow: each size's
prior objects are the smaller sizes' and more, as a lab's library grows. Each object's trials
are split by trial number: the first half builds the prior knowledge and is the pool the
learners observe, the second half is held out. Every learner starts with one observation of
each new object per action (step 0) and then chooses ``budget`` more. Methods: the baseline
(nothing of the prior), APTKT, APTKT with auxiliary features, the control (the prior's feature
space and kernel, no transfer), and at step 0 two nearest-neighbour rules on the same one-shot
observations: in the prior's feature space ("1-NN"), the plainest use of that metric, and in the
prior objects' within-object covariance of the table's own columns, shrunk towards its diagonal
and whitened ("1-NN shrunk", :data:`SHRUNK_COVARIANCE`) — the strongest simple rule the fitted
model should at least match. Methods are paired by group: the same new objects, the same pool
order, the same first observations, whatever the library size. With random priors at the
smallest library every learner also runs with uniformly random picks (``"APTKT random"``, ...),
so that its own choice of the next touch is measured against picking at random
(:mod:`aptkt.experiments.selection_report`).
"""

from __future__ import annotations

import math
import time
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import ConfigError, FeatureTableError
from aptkt.experiments.benchmark_settings import (
    PRIOR_CHOICES,
    BenchmarkSettings,
    check_enough_objects,
)
from aptkt.experiments.selection_report import CHECKED as CALIBRATED_LEARNERS
from aptkt.experiments.selection_report import CHOICE as RANDOM_PICKS_CHOICE
from aptkt.experiments.selection_report import random_arm
from aptkt.files import write_json_atomically, write_text_atomically
from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge
from aptkt.learning.feature_table import FeatureTable
from aptkt.learning.observations import Observations, ObservationTable
from aptkt.learning.pipeline import within_object_residuals

__all__ = [
    "PRIOR_CHOICES",
    "METHODS",
    "SHRUNK_COVARIANCE",
    "BenchmarkSettings",
    "Group",
    "draw_groups",
    "prior_choices",
    "split_trials",
    "run_group",
    "nearest_neighbour_accuracy",
    "shrunk_nearest_neighbour_accuracy",
    "run_benchmark",
]

#: The learners compared, by the name the results use.
METHODS: dict[str, dict[str, Any]] = {
    "baseline": {"transfer": "none", "auxiliary": False},
    "APTKT": {"transfer": "paper", "auxiliary": False},
    "APTKT+aux": {"transfer": "paper", "auxiliary": True},
    "control": {"transfer": "control", "auxiliary": False},
}
#: The reference rules' names in the results.
NEAREST_NEIGHBOUR = "1-NN"
SHRUNK_NEAREST_NEIGHBOUR = "1-NN shrunk"
#: The "1-NN shrunk" rule's metric: the prior objects' pooled within-object covariance C of the
#: table's columns, as ``(1 − s) C + s diag C``, whitened.
SHRUNK_COVARIANCE = 0.2


@dataclass(frozen=True)
class Group:
    """One group's new objects and, per library size and prior choice, its prior objects."""

    index: int
    new: tuple[str, ...]
    libraries: dict[int, dict[str, tuple[str, ...]]]


def split_trials(table: FeatureTable, actions: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Row masks (learn, test): per action and object, the first half of its rows by trial
    number (the prior's rows and the learners' pool) and the second half (held out)."""
    learn = np.zeros(len(table.trials), dtype=bool)
    for action in actions:
        for obj in table.object_names:
            rows = table.rows_of(obj, action)
            if rows.size < 2:
                raise FeatureTableError(
                    f"{table.path}: object {obj} has {rows.size} row(s) of action {action}; "
                    "the benchmark needs at least 2 (one to learn from, one held out)"
                )
            rows = rows[np.argsort(table.trials[rows], kind="stable")]
            learn[rows[: rows.size // 2]] = True
    test = np.isin(table.actions, list(actions)) & ~learn
    return learn, test


def object_distances(learn: ObservationTable) -> tuple[list[str], np.ndarray]:
    """How different every two objects are, independent of any model: the distance between
    their mean observations with each column divided by its pooled within-object standard
    deviation (how many noise levels apart), averaged over the actions."""
    objects = sorted({str(o) for obs in learn.values() for o in obs.objects})
    total = np.zeros((len(objects), len(objects)))
    for obs in learn.values():
        X = np.hstack([obs.modalities[m] for m in obs.modality_names])
        R, dof = within_object_residuals(X, obs.objects)
        noise = np.sqrt((R**2).sum(axis=0) / max(dof, 1))
        noise = np.where(noise > 0, noise, 1.0)
        means = np.array([X[obs.objects == o].mean(axis=0) for o in objects]) / noise
        total += np.sqrt(((means[:, None, :] - means[None, :, :]) ** 2).sum(axis=-1))
    return objects, total / len(learn)


def prior_choices(
    new: Sequence[str],
    candidates: Sequence[str],
    sizes: Sequence[int],
    distances: tuple[list[str], np.ndarray],
    rng: np.random.Generator,
) -> dict[int, dict[str, tuple[str, ...]]]:
    """The three ways of choosing ``k`` prior objects among ``candidates``, for each ``k`` in
    ``sizes``: at random; the ``k`` whose distance to the nearest new object is smallest
    ("nearest") or largest ("farthest"). Each way's larger libraries hold its smaller ones (one
    random order, one order by distance): a library that grows."""
    names, d = distances
    index = {o: i for i, o in enumerate(names)}
    closeness = {c: min(d[index[c], index[n]] for n in new) for c in candidates}
    order = sorted(candidates, key=lambda c: (closeness[c], c))
    shuffled = [str(c) for c in rng.permutation(list(candidates))]
    return {
        k: {
            "random": tuple(shuffled[:k]),
            "nearest": tuple(order[:k]),
            "farthest": tuple(order[::-1][:k]),
        }
        for k in sizes
    }


def draw_groups(
    objects: Sequence[str], distances: tuple[list[str], np.ndarray], s: BenchmarkSettings
) -> list[Group]:
    check_enough_objects(objects, s)
    rng = np.random.default_rng(s.seed)
    groups = []
    for g in range(s.groups):
        perm = [str(o) for o in rng.permutation(list(objects))]
        new, rest = perm[: s.new_objects], perm[s.new_objects :]
        chosen = prior_choices(new, rest, s.libraries, distances, rng)
        libraries = {k: {c: per[c] for c in s.choices} for k, per in chosen.items()}
        groups.append(Group(g, tuple(new), libraries))
    return groups


def nearest_neighbour_accuracy(
    prior: PriorKnowledge, first: ObservationTable, test: ObservationTable
) -> float:
    """Mean over actions of the test accuracy of 1-nearest-neighbour on the ``first``
    observations, in the prior's feature space (Euclidean over all its columns)."""
    accs = []
    for action, obs in first.items():
        X = prior[action].pipeline.transform(obs)[0]
        T = prior[action].pipeline.transform(test[action])[0]
        d = ((T[:, None, :] - X[None, :, :]) ** 2).sum(axis=-1)
        accs.append(float(np.mean(obs.objects[d.argmin(axis=1)] == test[action].objects)))
    return float(np.mean(accs))


def shrunk_nearest_neighbour_accuracy(
    prior_table: ObservationTable,
    first: ObservationTable,
    test: ObservationTable,
    shrinkage: float = SHRUNK_COVARIANCE,
) -> float:
    """Mean over actions of the test accuracy of 1-nearest-neighbour on the ``first``
    observations, in the metric of the prior objects' pooled within-object covariance C of the
    table's own columns (every modality side by side), shrunk as ``(1 − s) C + s diag C`` and
    whitened (Euclidean after multiplying by its inverse square root)."""
    accs = []
    for action, obs in first.items():
        old = prior_table[action]

        def columns(o: Observations) -> np.ndarray:
            return np.hstack([o.modalities[m] for m in o.modality_names])

        R, dof = within_object_residuals(columns(old), old.objects)
        C = R.T @ R / max(dof, 1)
        C = (1.0 - shrinkage) * C + shrinkage * np.diag(np.diag(C))
        vals, vecs = np.linalg.eigh(C)
        scale = max(float(vals.max()), 1e-300)
        W = vecs @ np.diag(1.0 / np.sqrt(np.maximum(vals, 1e-12 * scale))) @ vecs.T
        X, T = columns(obs) @ W, columns(test[action]) @ W
        d = ((T[:, None, :] - X[None, :, :]) ** 2).sum(axis=-1)
        accs.append(float(np.mean(obs.objects[d.argmin(axis=1)] == test[action].objects)))
    return float(np.mean(accs))


def _subset(table: ObservationTable, objects: Sequence[str]) -> dict[str, Observations]:
    return {a: obs.of_objects(objects) for a, obs in table.items()}


def same_period_accuracy(learner: APTKT, env: PoolEnvironment) -> float:
    """The learner's mean accuracy over the actions on the pool's touches it has not drawn:
    recorded in the same period as those it learned from (the first half of each object's
    trials), where the held-out touches were recorded later. The two differ by how much the
    sensor and the objects drifted in between, which no estimate from the learned touches can
    see. NaN where an action's pool is used up."""
    per_action = []
    for action, lrn in learner.learners.items():
        unused = env.unused(action)
        if len(unused) == 0 or lrn.model is None:
            per_action.append(math.nan)
            continue
        classes = np.array([str(c) for c in lrn.model.classes_])
        truth = unused.objects.astype(str)
        right = classes[np.argmax(lrn.predict_proba(unused), axis=1)] == truth
        # Each object once, as in the held-out touches (the pool keeps fewer of the objects
        # touched most, the confused ones).
        per_action.append(float(np.mean([right[truth == o].mean() for o in np.unique(truth)])))
    return float(np.mean(per_action))


def run_group(
    group: Group,
    learn: ObservationTable,
    test: ObservationTable,
    s: BenchmarkSettings,
    on_run: Callable[[], None] | None = None,
) -> list[dict[str, Any]]:
    """Every method's learning curve for one group: one row per (library size, prior choice,
    method, step). The baseline uses no prior, so it runs once and serves every library and
    choice. The features are transformed as the table's observations were computed (this
    skin's transforms only for this skin's features, see
    :func:`~aptkt.learning.pipeline.transforms_of`)."""
    actions = list(learn)
    new = list(group.new)
    pool = _subset(learn, new)
    held = _subset(test, new)
    seed = s.seed * 1_000_003 + group.index
    rows: list[dict[str, Any]] = []

    def run(
        cfg: LearnerConfig, prior: PriorKnowledge | None, *, calibrated: bool = False
    ) -> tuple[list[Any], APTKT]:
        """The run's curve: (held-out accuracy, the learner's own estimate, its accuracy on the
        pool's touches it did not draw) per step. The last costs a prediction per step, so it is
        measured only for the runs whose estimate is calibrated (NaN elsewhere)."""
        learner = APTKT(replace(cfg, budget=s.budget, seed=seed), prior)
        env = PoolEnvironment(pool, seed=seed)
        unused: list[float] = []
        result = learner.run(
            env,
            actions,
            new,
            test=held,
            on_step=lambda _: unused.append(
                same_period_accuracy(learner, env) if calibrated else math.nan
            ),
        )
        if on_run is not None:
            on_run()
        curve = [(st.mean_accuracy, st.estimated_accuracy) for st in result.steps]
        return [(a, e, u) for (a, e), u in zip(curve, unused)], learner

    base_cfg = replace(s.config, **METHODS["baseline"])
    baseline, base_learner = run(base_cfg, None, calibrated="baseline" in CALIBRATED_LEARNERS)
    # Each learner's random-picks arm, where the learners choose otherwise: with random priors
    # at the smallest library (the checks' size; at every size a sweep would take twice as
    # long).
    with_random_picks = s.config.selection != "random" and s.budget > 0
    base_random: list[Any] | None = None
    # The initial round's observations: the first row of each new object in every action.
    first = {
        a: lrn.observations.take(np.arange(len(new)))
        for a, lrn in base_learner.learners.items()
        if lrn.observations is not None
    }
    for size, per_choice in group.libraries.items():
        for choice, priors in per_choice.items():
            prior_table = _subset(learn, priors)
            prior = PriorKnowledge.build(
                prior_table,
                gp=s.config.gp,
                seed=seed + zlib.crc32(choice.encode()),
            )
            curves = {"baseline": baseline}
            for name, overrides in METHODS.items():
                if name != "baseline":
                    calibrated = choice == RANDOM_PICKS_CHOICE and name in CALIBRATED_LEARNERS
                    curves[name] = run(
                        replace(s.config, **overrides), prior, calibrated=calibrated
                    )[0]
            if with_random_picks and choice == RANDOM_PICKS_CHOICE and size == s.libraries[0]:
                if base_random is None:
                    base_random = run(replace(base_cfg, selection="random"), None)[0]
                curves[random_arm("baseline")] = base_random
                for name, overrides in METHODS.items():
                    if name != "baseline":
                        cfg = replace(s.config, **overrides, selection="random")
                        curves[random_arm(name)] = run(cfg, prior)[0]
            tags = {
                "group": group.index,
                "library": size,
                "priors": choice,
                "new_objects": ",".join(new),
                "prior_objects": ",".join(priors),
            }
            for name, curve in curves.items():
                rows += [
                    {
                        **tags,
                        "method": name,
                        "step": k,
                        "accuracy": v,
                        "estimated": e,
                        "same_period": u,
                    }
                    for k, (v, e, u) in enumerate(curve)
                ]
            for name, accuracy in (
                (NEAREST_NEIGHBOUR, nearest_neighbour_accuracy(prior, first, held)),
                (
                    SHRUNK_NEAREST_NEIGHBOUR,
                    shrunk_nearest_neighbour_accuracy(prior_table, first, held),
                ),
            ):
                rows.append({**tags, "method": name, "step": 0, "accuracy": accuracy})
    return rows


def benchmark(
    table: FeatureTable,
    s: BenchmarkSettings,
    *,
    parallel_map: Callable[[Callable[[Any], Any], Sequence[Any]], Any] | None = None,
    on_group: Callable[[int], None] | None = None,
) -> tuple[list[dict[str, Any]], float]:
    """Every group's rows (see :func:`run_group`) and the seconds it took."""
    t0 = time.perf_counter()
    actions = list(s.actions) if s.actions else table.action_names
    learn_rows, test_rows = split_trials(table, actions)
    learn = table.observations(actions, learn_rows)
    test = table.observations(actions, test_rows)
    distances = object_distances(learn)
    groups = draw_groups(table.object_names, distances, s)
    tasks = [(g, learn, test, s) for g in groups]
    rows: list[dict[str, Any]] = []
    for i, r in each_result(_task, tasks, parallel_map):
        rows += r
        if on_group is not None:
            on_group(i)
    rows.sort(key=lambda r: (r["group"], r["library"], r["priors"], r["method"], r["step"]))
    return rows, time.perf_counter() - t0


def _task(task: tuple[Group, ObservationTable, ObservationTable, BenchmarkSettings]):
    return run_group(*task)


def each_result(
    fn: Callable[[Any], Any],
    tasks: Sequence[Any],
    parallel_map: Callable[[Callable[[Any], Any], Sequence[Any]], Any] | None,
) -> Iterator[tuple[int, Any]]:
    """``(index, fn(task))`` for every task: here, in order, or as ``parallel_map`` (an
    executor's ``imap_unordered``) delivers them."""
    if parallel_map is None:
        return ((i, fn(t)) for i, t in enumerate(tasks))
    return iter(parallel_map(fn, tasks))


def parallel_map_of(executor: Any, jobs: int, scheduler: Any) -> Any:
    """The executor's map where work leaves this process (a cluster, or several jobs)."""
    return executor.imap_unordered if scheduler is not None or jobs > 1 else None


def run_benchmark(
    table: FeatureTable,
    s: BenchmarkSettings,
    *,
    output: Path,
    jobs: int = 1,
    scheduler: Any = None,
    command: str = "",
    progress: bool = True,
    say: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Run the benchmark and write its files to ``output``: results.csv (every group's curves),
    summary.json (settings, mean curves, paired gains, checks), report.md, benchmark.png/.svg
    and, with several library sizes, library.png/.svg. Groups run on ``jobs`` local processes,
    or on the Dask cluster at ``scheduler``. Returns the summary (its "checks" say which
    held)."""
    from aptkt import __version__
    from aptkt.experiments import benchmark_report as br
    from aptkt.experiments import selection_report as sr
    from aptkt.experiments.executors import make_executor
    from aptkt.experiments.noise_profile import noise_profile
    from aptkt.experiments.plots import save_figure
    from aptkt.experiments.tables import write_csv
    from aptkt.progress import Progress

    actions = list(s.actions) if s.actions else table.action_names
    # Before the heading: a mistake is one line, with nothing printed before it.
    check_enough_objects(table.object_names, s)
    executor = make_executor(jobs, scheduler)
    sizes = ", ".join(str(k) for k in s.libraries)
    say(
        f"{table.path}: {len(table.object_names)} objects, action(s) {', '.join(actions)}; "
        f"{s.groups} groups of {s.new_objects} new objects with {sizes} priors "
        f"({', '.join(s.choices)}), budget {s.budget}, on {executor.description}"
    )
    bar = Progress(s.groups, "group", "benchmark", enabled=progress)
    try:
        rows, seconds = benchmark(
            table,
            s,
            parallel_map=parallel_map_of(executor, jobs, scheduler),
            on_group=lambda _i: bar.update(1),
        )
    finally:
        executor.close()
        bar.close()
    output.mkdir(parents=True, exist_ok=True)
    write_csv(output / "results.csv", rows)
    c = br.curves(rows)
    against_random = sr.compare(c)
    calibration = sr.calibrate(c, br.curves(rows, "estimated"), br.curves(rows, "same_period"))
    found = br.checks(c) + sr.checks(against_random) + sr.calibration_checks(calibration)
    head = {
        "table": str(table.path),
        "command": command,
        "software_version": __version__,
        "seconds": seconds,
        "jobs": jobs if scheduler is None else executor.description,
        "date": time.strftime("%Y-%m-%d"),
        "objects": len(table.object_names),
        "actions": actions,
        "groups": s.groups,
        "new": s.new_objects,
        "libraries": list(s.libraries),
        "budget": s.budget,
        "selection": s.config.selection,
    }
    chance = 1.0 / s.new_objects
    save_figure(br.plot(c, chance), output / "benchmark")
    written = [output / "report.md", output / "benchmark.png"]
    if against_random:
        save_figure(sr.plot(c, against_random[0].library), output / "selection")
        written.append(output / "selection.png")
    if len(s.libraries) > 1 and "random" in s.choices:
        save_figure(br.plot_library(c), output / "library")
        written.append(output / "library.png")
    summary = {
        **head,
        "learner": s.config.to_dict(),
        "choices": list(s.choices),
        "results": br.summary(c),
        "active_against_random": [r.as_dict() for r in against_random],
        "own_estimate": [k.as_dict() for k in calibration],
        "checks": [k.as_dict() for k in found],
    }
    profiles = noise_profile(table.observations(actions))
    summary["noise_profile"] = [p.as_dict() for p in profiles]
    write_json_atomically(output / "summary.json", summary, ConfigError)
    report = br.report_markdown(c, head, found, profiles)
    report += "\n" + "\n".join(
        sr.report_lines(against_random, len(s.libraries))
        + sr.calibration_lines(calibration, len(s.libraries))
    )
    write_text_atomically(output / "report.md", report, ConfigError)
    br.announce_checks(found, say)
    say(
        f"{br.checks_line(found)}; done in {seconds:.0f} s: "
        f"{', '.join(str(p) for p in written)}, {output / 'results.csv'}"
    )
    return summary
