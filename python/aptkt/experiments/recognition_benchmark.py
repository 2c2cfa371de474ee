"""The recognition benchmark (``aptkt benchmark TABLE --recognition``) on any sensor's feature
table: in each of ``groups`` random draws, a library of ``library`` objects built from the first
half of their trials, and touches to recognise — the second half of their trials and the second
half of ``unseen`` objects the library does not hold. Measured per draw: the accuracy on the
library's objects, a nearest-class-mean rule's on the same touches in the library's metric,
the novelty AUROC, and the shares of known and unseen objects' touches flagged as new at the
threshold chosen on the library."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import ConfigError
from aptkt.experiments.aggregate import estimate
from aptkt.experiments.benchmark import split_trials
from aptkt.experiments.benchmark_settings import check_recognition_objects
from aptkt.experiments.report import ci, markdown_table
from aptkt.files import write_json_atomically, write_text_atomically
from aptkt.learning import PriorKnowledge
from aptkt.learning.feature_table import FeatureTable

__all__ = ["recognition_draw", "run_recognition_benchmark", "METRICS"]

METRICS = {
    "accuracy": "accuracy on the library's objects",
    "ncm": "nearest class mean, same touches and metric",
    "auroc": "novelty AUROC",
    "false_alarms": "known objects' touches flagged as new",
    "detected": "unseen objects' touches flagged as new",
}


def recognition_draw(
    table: FeatureTable, actions: list[str], library: list[str], unseen: list[str], seed: int
) -> dict[str, float]:
    learn_rows, test_rows = split_trials(table, actions)
    learn = table.observations(actions, learn_rows)
    test = table.observations(actions, test_rows)
    prior = PriorKnowledge.build(
        {a: o.of_objects(library) for a, o in learn.items()},
        seed=seed,
    )
    touches = {a: o.of_objects(library + unseen) for a, o in test.items()}
    result = prior.recognise(touches)
    from aptkt.experiments.lifelong import nearest_class_mean_accuracy

    mine = result.in_library()
    return {
        "accuracy": float(result.accuracy() or 0.0),
        "ncm": nearest_class_mean_accuracy(
            prior, {a: o.of_objects(library) for a, o in test.items()}
        ),
        "auroc": float(result.novelty_auroc() or float("nan")),
        "false_alarms": float(np.mean(~result.known[mine])),
        "detected": float(np.mean(~result.known[~mine])),
    }


def _task(task: tuple[FeatureTable, list[str], list[str], list[str], int]) -> dict[str, float]:
    return recognition_draw(*task)


def run_recognition_benchmark(
    table: FeatureTable,
    *,
    groups: int,
    library: int,
    unseen: int,
    seed: int,
    actions: list[str] | None,
    output: Path,
    jobs: int = 1,
    command: str = "",
    say: Callable[[str], None] = print,
) -> dict[str, Any]:
    from aptkt import __version__
    from aptkt.experiments.executors import make_executor
    from aptkt.experiments.tables import write_csv

    names = actions or table.action_names
    objects = table.object_names
    check_recognition_objects(objects, library, unseen)
    rng = np.random.default_rng(seed)
    draws = []
    for _ in range(groups):
        perm = [str(o) for o in rng.permutation(objects)]
        draws.append((perm[:library], perm[library : library + unseen]))
    say(
        f"{table.path}: {len(objects)} objects; {groups} draws of a library of {library} and "
        f"{unseen} objects it does not hold"
    )
    t0 = time.perf_counter()
    tasks = [(table, names, lib, new, seed + g) for g, (lib, new) in enumerate(draws)]
    executor = make_executor(jobs)
    try:
        results = dict(
            executor.imap_unordered(_task, tasks) if jobs > 1 else enumerate(map(_task, tasks))
        )
    finally:
        executor.close()
    rows = [
        {"draw": g, "library": ",".join(draws[g][0]), "unseen": ",".join(draws[g][1]), **results[g]}
        for g in range(groups)
    ]
    output.mkdir(parents=True, exist_ok=True)
    write_csv(output / "results.csv", rows)
    summary: dict[str, Any] = {
        "table": str(table.path),
        "command": command,
        "software_version": __version__,
        "seconds": time.perf_counter() - t0,
        "draws": groups,
        "library": library,
        "unseen": unseen,
        "results": {},
    }
    lines = []
    for key, what in METRICS.items():
        e = estimate([r[key] for r in rows], units=list(range(groups)), unit_name="draw")
        summary["results"][key] = e.as_dict()
        lines.append(
            [
                what,
                f"{e.mean:.3f}",
                f"[{e.low:.3f}, {e.high:.3f}]"
                if e.why_no_interval is None
                else f"no interval ({e.why_no_interval})",
                f"{min(r[key] for r in rows):.3f}",
            ]
        )
    diff = estimate(
        [r["accuracy"] - r["ncm"] for r in rows], units=list(range(groups)), unit_name="draw"
    )
    summary["results"]["accuracy - ncm"] = diff.as_dict()
    write_json_atomically(output / "summary.json", summary, ConfigError)
    report = [
        f"# Recognition benchmark: {table.path}",
        "",
        f"Command: `{command}`  ",
        f"aptkt {__version__}; {summary['seconds']:.0f} s; {time.strftime('%Y-%m-%d')}.",
        "",
        f"{groups} random draws: a library of {library} objects from the first half of their "
        f"trials; touches: the second half of their trials and of {unseen} objects it does not "
        "hold. The novelty threshold is chosen on each library for a false-alarm rate of 5 %.",
        "",
        markdown_table(["", "mean", "95 % interval", "lowest draw"], lines),
        "",
        f"Accuracy − nearest class mean, paired by draw: {ci(diff)}.",
        "",
    ]
    write_text_atomically(output / "report.md", "\n".join(report), ConfigError)
    for what, mean, interval, lowest in lines:
        say(f"  {what}: {mean} {interval} (lowest {lowest})")
    say(f"done: {output / 'report.md'}, {output / 'results.csv'}")
    return summary
