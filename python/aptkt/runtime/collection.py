"""Collect a data set on a live session (the UR10 with its skin, or the simulated world).

Trial by trial, into the crash-safe store (:class:`~aptkt.data.DatasetWriter`): each
recording is flushed before the next action starts, so a process killed at any moment leaves
every completed trial readable. ``resume`` skips the trials already stored.

A robot or skin fault mid-action stops the collection: the backend has stopped the arm; the
partial recording goes to the side file ``<name>.aborted<suffix>`` (``data.h5`` →
``data.aborted.h5``; a second abort of the same trial goes to ``data.aborted-2.h5``, ...), its
metadata flagged ``aborted`` with the error; and :class:`CollectionAborted` names the object,
action and trial. A fault *after* a complete action (while lifting off or waiting) keeps that
trial in the data set itself, with the error in its metadata (:mod:`aptkt.runtime.salvage`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aptkt.actions import ExploratoryAction
from aptkt.data import DatasetWriter
from aptkt.errors import AptktError, ConfigError
from aptkt.runtime.grid import TrialGrid
from aptkt.runtime.salvage import aborted_path, note_interruption, salvage, save_aborted
from aptkt.runtime.trial_file import TrialFile

__all__ = ["CollectionPlan", "CollectionAborted", "collect", "aborted_path", "save_aborted"]


@dataclass(frozen=True)
class CollectionPlan(TrialGrid):
    """Every action ``repetitions`` times on every object, trial numbers from ``first_trial``."""

    objects: tuple[str, ...]
    actions: tuple[ExploratoryAction, ...]
    repetitions: int
    first_trial: int = 0

    def __post_init__(self) -> None:
        if not self.objects or not self.actions:
            raise ConfigError("a collection needs at least one object and one action")
        if self.repetitions < 1 or self.first_trial < 0:
            raise ConfigError("-n must be >= 1 and --first-trial >= 0")
        for kind, names in (
            ("object", list(self.objects)),
            ("action", [a.name for a in self.actions]),
        ):
            if len(set(names)) != len(names):
                raise ConfigError(f"each {kind} may appear once, got {names}")

    def describe(self) -> dict[str, Any]:
        return {
            "objects": list(self.objects),
            "actions": [a.to_dict() for a in self.actions],
            "repetitions": self.repetitions,
            "first_trial": self.first_trial,
        }


class CollectionAborted(AptktError):
    """A fault stopped the collection in the middle of a trial (the arm is stopped).

    ``object``, ``action``, ``trial``: the trial; ``cause``: the robot or skin error;
    ``saved``: where its recording went (None if nothing was being recorded);
    ``completed``: recordings in the data set now.
    """

    def __init__(
        self,
        message: str,
        *,
        object: str,
        action: str,
        trial: int,
        cause: BaseException,  # noqa: A002
        saved: Path | None,
        completed: int,
    ):
        super().__init__(message)
        self.object, self.action, self.trial = object, action, trial
        self.cause, self.saved, self.completed = cause, saved, completed


def _check_resumable(
    path: Path, desc: Mapping[str, Any], plan: CollectionPlan, session: Mapping[str, Any]
) -> None:
    stored = desc.get("session", {})
    if stored.get("robot") and stored.get("robot") != session.get("robot"):
        raise ConfigError(
            f"{path} was collected with --robot {stored['robot']}, not {session.get('robot')}: "
            "use another output file"
        )
    if session.get("robot") == "sim" and stored.get("seed") not in (None, session.get("seed")):
        raise ConfigError(
            f"{path} was simulated with --seed {stored['seed']}, not {session.get('seed')}"
        )
    before = {a["name"]: a for a in desc.get("actions", [])}
    for action in plan.actions:
        old = before.get(action.name)
        if old is not None and old != action.to_dict():
            raise ConfigError(
                f"{path}: action {action.name!r} was recorded with other parameters "
                f"({json.dumps(old)}); resume with the same definition or rename it"
            )


def collect(
    path: str | Path,
    plan: CollectionPlan,
    session: Any,
    *,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool | Callable[[str], None] = True,
    between_trials: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Run ``plan`` on ``session`` (an entered :mod:`aptkt.runtime.sessions` session) into ``path``.

    ``progress``: True for a progress bar on stderr, or a callable that receives one line per
    recording. ``between_trials(trial)`` is called before each new trial round but the first
    (e.g. to let an operator re-place the objects). Returns a summary of the file. Raises
    :class:`CollectionAborted` on a fault mid-trial.
    """
    t0 = time.perf_counter()
    session_desc = session.describe()
    description = {"collector": "aptkt collect", "session": session_desc, **plan.describe()}
    collected = 0
    current_round: int | None = None
    with TrialFile(
        path,
        plan,
        description=description,
        resume=resume,
        overwrite=overwrite,
        check=lambda stored: _check_resumable(Path(path), stored, plan, session_desc),
        progress=progress is True,
    ) as out:
        writer, bar = out.writer, out.bar
        for obj, action, trial in out.todo:
            if trial != current_round:
                if current_round is not None and between_trials is not None:
                    if bar is not None:
                        bar.clear()
                    between_trials(trial)
                current_round = trial
            if bar is not None:
                bar.note(f"{obj} {action.name} trial {trial}")
            try:
                rec = session.explore(obj, action, trial)
            except KeyboardInterrupt as exc:
                _aborted(out.path, writer, obj, action, trial, exc)
                raise
            except AptktError as exc:
                raise _aborted(out.path, writer, obj, action, trial, exc) from exc
            writer.append(rec)
            collected += 1
            if bar is not None:
                bar.update(1)
            elif callable(progress):
                progress(
                    f"[{len(writer)}/{len(plan)}] {obj} {action.name} trial {trial}: "
                    f"{len(rec.samples)} samples, {rec.duration:.2f} s"
                )
    return out.summary(
        collected=collected,
        skipped=len(plan) - len(out.todo),
        planned=len(plan),
        wall_seconds=time.perf_counter() - t0,
    )


def _aborted(
    path: Path,
    writer: DatasetWriter,
    obj: str,
    action: ExploratoryAction,
    trial: int,
    exc: BaseException,
) -> BaseException:
    """Save what the failed trial recorded; the error to raise in its place."""
    kept = salvage(exc, writer, path)
    if isinstance(exc, KeyboardInterrupt):
        note_interruption(exc, f"{obj} / {action.name} / trial {trial}", kept)
        return exc
    cause = kept.cause
    message = (
        f"{obj} / {action.name} / trial {trial}: {type(cause).__name__}: {cause}. The robot was stopped; "
        f"{kept.what}. {len(writer)} complete recordings are in {path}; run the same command with --resume "
        "to continue (after clearing the fault)."
    )
    return CollectionAborted(
        message,
        object=obj,
        action=action.name,
        trial=trial,
        cause=cause,
        saved=kept.saved,
        completed=len(writer),
    )
