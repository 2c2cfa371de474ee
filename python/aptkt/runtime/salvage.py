"""What a failed trial recorded is never lost: the one rule both ``aptkt collect`` and
``aptkt learn`` apply to a fault.

A :class:`~aptkt.errors.TrialFault` (or :class:`~aptkt.errors.TrialInterrupted`) whose action
had completed keeps its trial in the data set itself, the fault noted in its metadata
(``fault_after_recording``). A partial recording goes to the side file ``<name>.aborted<suffix>``
(``data.h5`` → ``data.aborted.h5``; a second abort of the same trial goes to
``data.aborted-2.h5``, ...), its metadata flagged ``aborted`` with the error. A fault before the
recording started leaves nothing to keep.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from aptkt.data import DatasetWriter
from aptkt.data.codec import recording_key
from aptkt.errors import AptktError, DatasetError, TrialFault, TrialInterrupted
from aptkt.skin.samples import Recording

__all__ = ["Salvaged", "aborted_path", "save_aborted", "salvage", "note_interruption"]


def aborted_path(path: str | Path, attempt: int = 1) -> Path:
    """Side file for partial recordings: ``data.h5`` → ``data.aborted.h5`` (``-2``, ... after)."""
    path = Path(path)
    tag = ".aborted" if attempt <= 1 else f".aborted-{attempt}"
    return path.with_name(path.stem + tag + path.suffix)


def save_aborted(path: str | Path, rec: Recording, error: BaseException) -> Path:
    """Store a partial recording in the side file of data set ``path``; returns the file used."""
    rec.metadata.setdefault("aborted", f"{type(error).__name__}: {error}")
    rec.metadata["error_type"] = type(error).__name__
    key = recording_key(rec)
    for attempt in range(1, 1000):
        target = aborted_path(path, attempt)
        try:
            with DatasetWriter(target, "a", description={"aborted_recordings_of": str(path)}) as w:
                if key in w.keys():
                    continue
                w.append(rec)
                return target
        except DatasetError:
            continue  # a side file whose writer died: leave it for inspection, use the next
    raise DatasetError(f"no free side file for the partial recording of {key} next to {path}")


@dataclass(frozen=True)
class Salvaged:
    """The outcome of :func:`salvage`: the robot or skin error behind the fault, where its
    recording went (None if nowhere), and one sentence saying so."""

    cause: BaseException
    saved: Path | None
    what: str


def note_interruption(exc: KeyboardInterrupt, where: str, kept: Salvaged, *more: str) -> None:
    """Name the interrupted trial and where its recording went on the ``KeyboardInterrupt``
    (SIGINT or SIGTERM) itself: the command line prints its notes in its one closing line."""
    if sys.version_info >= (3, 11):  # notes on exceptions are new in 3.11
        exc.add_note("; ".join((f"interrupted at {where}", kept.what, *more)))


def salvage(exc: BaseException, writer: DatasetWriter, path: Path) -> Salvaged:
    """Keep what the failed trial behind ``exc`` recorded, in the data set ``path`` being
    written by ``writer`` (a complete recording) or in its side file (a partial one)."""
    if not isinstance(exc, (TrialFault, TrialInterrupted)):
        return Salvaged(exc, None, "nothing was being recorded")
    rec, cause = exc.recording, exc.cause
    if exc.complete and not rec.silent_cells:
        # The action completed; the fault came while lifting off or waiting: keep the trial.
        rec.metadata["fault_after_recording"] = f"{type(cause).__name__}: {cause}"
        writer.append(rec)
        return Salvaged(cause, path, f"the trial's recording was complete and is stored in {path}")
    try:
        saved = save_aborted(path, rec, cause)
    except (AptktError, OSError, ValueError) as save_exc:
        return Salvaged(cause, None, f"its partial recording could not be saved: {save_exc}")
    return Salvaged(
        cause,
        saved,
        f"its partial recording ({len(rec.samples)} samples, {rec.duration:.2f} s) is in {saved}"
        " (flagged 'aborted')",
    )
