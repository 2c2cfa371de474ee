"""Learning live: APTKT (or the baseline) on a robot that explores on request.

The environment is a :class:`~aptkt.learning.environment.RecordingEnvironment` over a live
session (:mod:`aptkt.runtime.sessions`: the UR10 with its skin, or the simulated world). Every observation
the learner asks for runs the exploratory action and its recording is stored at once in a data
set (the crash-safe store), so nothing observed is lost, even if the run is not finished.

A live run has no test set: the accuracy the paper reports needs held-out observations of the
same objects, which only a data set given with ``test=`` provides. Without it the run reports
the models' own uncertainty and the transfer decisions, and no accuracy.

The output directory receives ``run.json`` (configuration, objects, actions, every step with
its transfer decisions, the status), ``steps.csv`` (one row per step), ``transfer.csv`` (one
row per step, action and new object) and ``learned_prior.npz``: the new objects' observations
with their fitted models, a :class:`~aptkt.learning.PriorKnowledge` that later runs can load
as prior knowledge.
"""

from __future__ import annotations

import csv
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from aptkt import __version__
from aptkt.actions import ExploratoryAction
from aptkt.data import DatasetReader, DatasetWriter
from aptkt.errors import AptktError, ConfigError
from aptkt.files import open_atomically, write_json_atomically
from aptkt.learning.config import LearnerConfig
from aptkt.learning.environment import PrefetchedEnvironment, RecordingEnvironment
from aptkt.learning.extract import ExtractionSettings
from aptkt.learning.learner import APTKT, StepRecord
from aptkt.learning.observations import ObservationTable
from aptkt.learning.prior import PriorKnowledge
from aptkt.learning.transfer_summary import describe, final_decisions, summary_lines
from aptkt.runtime.salvage import Salvaged, note_interruption, salvage

__all__ = ["LiveLearningAborted", "learn_live", "describe_step", "NO_TEST_NOTE"]

NO_TEST_NOTE = (
    "no test set: accuracy is not reported (a live run has no held-out observations; "
    "pass a data set of the same objects as test data to measure it)"
)


class LiveLearningAborted(AptktError):
    """A robot or skin fault stopped a live learning run; ``cause`` is the error, ``saved``
    where the failed action's recording went, ``output`` the directory with the run so far."""

    def __init__(self, message: str, *, cause: BaseException, saved: Path | None, output: Path):
        super().__init__(message)
        self.cause, self.saved, self.output = cause, saved, output


def describe_step(rec: StepRecord, config: LearnerConfig, n_pairs: int) -> str:
    """One progress line: what was chosen and why, what transfers, and accuracy if known."""
    if rec.action is None:
        head = f"step   0: initial round done ({rec.n_observations} observations, every action on every object)"
    else:
        if rec.explored or config.selection == "random":
            why = "random pick" + (", eps-exploration" if config.selection != "random" else "")
        elif config.selection == "error-reduction":
            why = f"most error expected removed of {n_pairs} pairs: {rec.expected_gain:.3f}"
        else:
            why = f"highest uncertainty of {n_pairs} pairs"
        head = (
            f"step {rec.step:3d}/{config.budget}: {rec.action} on {rec.object}, uncertainty "
            f"{rec.uncertainty:.3f} ({why})"
        )
    parts = [head]
    for action, decisions in rec.transfer.items():
        if not config.transfers:
            continue
        text = "; ".join(describe(d, config) for d in decisions.values())
        parts.append(f"    transfer {action}: {text}")
    if not math.isnan(rec.estimated_accuracy):
        parts.append(f"    estimated accuracy {rec.estimated_accuracy:.3f} (its own, no test data)")
    if not math.isnan(rec.mean_accuracy):
        parts.append(f"    test accuracy {rec.mean_accuracy:.3f} (fused {rec.fused_accuracy:.3f})")
    return "\n".join(parts)


def _next_trial(path: Path) -> int:
    """Trial numbers continue after the largest one already in the record file."""
    if not path.exists():
        return 0
    with DatasetReader(path) as rd:
        trials = [t for _, _, t in rd.keys()]
    return max(trials) + 1 if trials else 0


def learn_live(
    session: Any,
    prior: PriorKnowledge | None,
    config: LearnerConfig,
    actions: Mapping[str, ExploratoryAction],
    new_objects: Sequence[str],
    *,
    record: str | Path,
    output: str | Path,
    test: ObservationTable | None = None,
    report: Callable[[str], None] = print,
    extra: Mapping[str, Any] | None = None,
    recognise_first: bool = False,
) -> dict[str, Any]:
    """Run APTKT on an entered live ``session``; write the run to ``output``; return the summary.

    ``recognise_first``: ``new_objects`` are candidates. Each is touched once with every action
    and recognised with the library (:meth:`PriorKnowledge.recognise`); the known ones are
    reported and left alone, the ones the library flags as new are learned (their touches are
    the learner's first round: the robot does not repeat them).

    Every recording is appended to the data set ``record`` (created if missing; trial numbers
    continue after the ones it holds). Raises :class:`LiveLearningAborted` after a fault, once
    the run so far is written.
    """
    t0 = time.perf_counter()
    output, record = Path(output), Path(record)
    output.mkdir(parents=True, exist_ok=True)
    first_trial = _next_trial(record)
    steps: list[StepRecord] = []
    n_pairs = len(actions) * len(new_objects)
    summary: dict[str, Any] = {
        "software_version": __version__,
        "session": session.describe(),
        "prior": {
            "objects": prior.objects if prior else [],
            "actions": list(prior.actions) if prior else [],
            # The loaded file's own scale: config.gp's applies to the learned prior only.
            "feature_scale": prior.feature_scale if prior else None,
            **dict((extra or {}).get("prior", {})),
        },
        "config": config.to_dict(),
        "actions": {name: a.to_dict() for name, a in actions.items()},
        "new_objects": list(new_objects),
        "record_file": str(record),
        "first_trial": first_trial,
        "test": dict((extra or {}).get("test", {})) if test is not None else None,
        "accuracy_reported": test is not None,
    }
    if test is None:
        summary["note"] = NO_TEST_NOTE

    writer = DatasetWriter(
        record,
        "a",
        description={
            "collector": "aptkt learn",
            "session": summary["session"],
            "actions": list(summary["actions"].values()),
        },
    )
    failure: dict[str, Any] = {}
    # Where the run is between trials, for an interruption there (no trial to name).
    progress = {"phase": "the first round of touches", "last": "no trial yet"}

    def explore(obj: str, action: ExploratoryAction, trial: int) -> Any:
        report(f"  exploring {obj} with {action.name} (trial {trial})")
        try:
            recording = session.explore(obj, action, trial)
            progress["last"] = f"{obj} / {action.name} / trial {trial}"
            return recording
        except (AptktError, KeyboardInterrupt) as exc:
            kept = salvage(exc, writer, record)
            failure.update(
                object=obj,
                action=action.name,
                trial=trial,
                cause=kept.cause,
                saved=kept.saved,
                what=kept.what,
                kept=kept,
            )
            raise

    def on_step(rec: StepRecord) -> None:
        steps.append(rec)
        progress["phase"] = f"learning after step {rec.step}"
        report(describe_step(rec, config, n_pairs))

    env: Any = RecordingEnvironment(
        explore, actions, first_trial=first_trial, on_recording=writer.append
    )
    learner = APTKT(config, prior)
    if test is None:
        report(f"note: {NO_TEST_NOTE}")
    status = "completed"
    try:
        if recognise_first:
            assert prior is not None  # recognition needs a library
            progress["phase"] = "the recognition touches"
            touched = _recognise(env, prior, list(actions), list(new_objects), report)
            summary["recognition"] = touched["rows"]
            new_objects = touched["new"]
            summary["new_objects"] = list(new_objects)
            if len(new_objects) < 2:
                report(
                    f"{len(new_objects)} new object(s): learning needs at least two; the "
                    "recognition is in run.json"
                )
                summary["status"] = "recognised"
                summary["seconds"] = time.perf_counter() - t0
                write_json_atomically(output / "run.json", summary, ConfigError, indent=2)
                return summary
            env = PrefetchedEnvironment(env, touched["observations"])
        run = learner.run(env, list(actions), list(new_objects), test=test, on_step=on_step)
        summary["stopped_early"] = run.stopped_early
        summary["stop_reason"] = run.stop_reason
        if run.stop_reason is not None:
            status = f"completed (stopped early: {run.stop_reason})"
    except (AptktError, KeyboardInterrupt) as exc:
        if not failure and isinstance(exc, KeyboardInterrupt):
            # Ctrl-C between trials (recognising, updating the models): no recording was under
            # way; the run so far is written as after an interruption mid-trial.
            summary["stopped_early"] = True
            summary["interrupted"] = {"during": progress["phase"], "after": progress["last"]}
            _finish(summary, steps, learner, config, output, "interrupted", t0, report)
            note_interruption(
                exc,
                f"{progress['phase']}, after {progress['last']}",
                Salvaged(exc, None, "no trial was under way"),
                f"every completed recording is in {record}",
                f"the run so far ({len(steps)} steps) is in {output}",
            )
            raise
        if not failure:
            raise  # not a fault of the robot or skin (e.g. a learning error): nothing to add
        cause = failure["cause"]
        status = f"aborted: {type(cause).__name__}: {cause}"
        summary["stopped_early"] = True
        summary["fault"] = {
            "object": failure["object"],
            "action": failure["action"],
            "trial": failure["trial"],
            "error": f"{type(cause).__name__}: {cause}",
            "recording_saved_to": str(failure["saved"]) if failure.get("saved") else None,
        }
        _finish(summary, steps, learner, config, output, status, t0, report)
        if isinstance(exc, KeyboardInterrupt):
            note_interruption(
                exc,
                f"{failure['object']} / {failure['action']} / trial {failure['trial']}",
                failure["kept"],
                f"every completed recording is in {record}",
                f"the run so far ({len(steps)} steps) is in {output}",
            )
            raise
        raise LiveLearningAborted(
            f"{failure['object']} / {failure['action']} / trial {failure['trial']}: {type(cause).__name__}: {cause}. "
            f"The robot was stopped; {failure['what']}; every completed recording is in {record}; the run so far "
            f"({len(steps)} steps) is in {output}.",
            cause=cause,
            saved=failure["saved"],
            output=output,
        ) from exc
    finally:
        writer.close()
    _finish(summary, steps, learner, config, output, status, t0, report)
    return summary


def _recognise(
    env: Any,
    prior: PriorKnowledge,
    actions: list[str],
    candidates: list[str],
    report: Callable[[str], None],
) -> dict[str, Any]:
    """Touch each candidate once with every action and recognise it with the library: its
    rows, the observations made, and the candidates flagged as new."""
    from aptkt.learning.observations import Observations

    made: dict[tuple[str, str], Mapping[str, np.ndarray]] = {}
    parts: dict[str, list[Observations]] = {a: [] for a in actions}
    for obj in candidates:
        for action in actions:
            observation = env.observe(action, obj)
            made[(action, obj)] = observation
            # One touch: the same trial number for every action of it.
            parts[action].append(Observations.single(action, obj, observation, 0))
    table = {a: Observations.concat(p) for a, p in parts.items()}
    result = prior.recognise(table)
    new = []
    for row in result.rows():
        if not row["known"] and row["object"] in prior.objects:
            report(
                f"recognised: {row['object']} is new (novelty {row['novelty']:.1f}), but the "
                "library holds an object of that name: not learned again (rename it to learn it "
                "as a new object)"
            )
        elif row["known"]:
            report(
                f"recognised: {row['object']} is {row['predicted']} (probability "
                f"{row['probability']:.2f}, runner-up {row['runner_up']}, novelty "
                f"{row['novelty']:.1f})"
            )
        else:
            new.append(row["object"])
            report(
                f"recognised: {row['object']} is new (novelty {row['novelty']:.1f} > "
                f"{result.calibration.threshold:.1f}; most like {row['predicted']})"
            )
    return {"rows": result.rows(), "new": new, "observations": made}


def _finish(
    summary: dict[str, Any],
    steps: list[StepRecord],
    learner: APTKT,
    config: LearnerConfig,
    output: Path,
    status: str,
    t0: float,
    report: Callable[[str], None],
) -> None:
    summary["status"] = status
    summary["steps"] = [
        {**s.as_row(), "accuracy": s.accuracy, "transfer": s.transfer} for s in steps
    ]
    summary["observations"] = {
        a: {o: lrn.count(o) for o in lrn.new_objects} for a, lrn in learner.learners.items()
    }
    learned = output / "learned_prior.npz"
    table = {
        a: lrn.observations for a, lrn in learner.learners.items() if lrn.observations is not None
    }
    summary["learned_prior"] = None
    if table:
        try:
            # In the loaded library's metric, so that the two merge (aptkt prior merge).
            gp = config.gp
            if learner.prior is not None:
                gp = replace(gp, prior_feature_scale=learner.prior.feature_scale)
            new = PriorKnowledge.build(table, gp=gp, seed=config.seed)
            new.metadata.update(
                action_definitions=summary.get("actions", {}),
                extraction=ExtractionSettings().to_dict(),
            )
            new.save(learned)
            summary["learned_prior"] = str(learned)
        except ValueError as exc:  # e.g. an action observed on one object only (an early fault)
            summary["learned_prior_error"] = str(exc)
    summary["seconds"] = time.perf_counter() - t0
    write_json_atomically(output / "run.json", summary, ConfigError, indent=2)
    _write_steps(output / "steps.csv", steps)
    _write_transfer(output / "transfer.csv", steps)
    if config.transfers and steps:
        report("transfer at the end (per action: new object <- prior object, or why not):")
        for line in summary_lines([final_decisions(steps)], config):
            report("  " + line)
    report(
        f"{status}: {len(steps)} steps in {summary['seconds']:.1f} s; run written to {output / 'run.json'}, "
        f"{output / 'steps.csv'}, {output / 'transfer.csv'}"
        + (
            f"; the new objects' observations and models in {learned}"
            if summary.get("learned_prior")
            else ""
        )
    )


def _write_steps(path: Path, steps: Sequence[StepRecord]) -> None:
    rows = [s.as_row() for s in steps]
    keys: list[str] = []
    for r in rows:
        keys.extend(k for k in r if k not in keys)
    with open_atomically(path, ConfigError, newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys or ["step"])
        w.writeheader()
        w.writerows(rows)


def _write_transfer(path: Path, steps: Sequence[StepRecord]) -> None:
    with open_atomically(path, ConfigError, newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["step", "action", "new_object", "source", "lambda", "mean_posterior"])
        for s in steps:
            for action, decisions in s.transfer.items():
                for obj, d in decisions.items():
                    w.writerow(
                        [
                            s.step,
                            action,
                            obj,
                            d.get("source") or "",
                            d.get("lambda"),
                            json.dumps(d.get("mean_posterior", {}), sort_keys=True),
                        ]
                    )
