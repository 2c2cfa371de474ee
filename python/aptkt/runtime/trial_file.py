"""The data set a plan of trials fills, shared by the simulated generator and the collection
on a robot: a fresh file, or an existing one resumed — repaired first if its writer died, the
trials it holds skipped — and the progress bar over the whole plan."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from aptkt.actions import ExploratoryAction
from aptkt.data import DatasetReader, DatasetWriter, repair
from aptkt.data.lock import WriterLock
from aptkt.errors import DatasetError
from aptkt.progress import Progress
from aptkt.runtime.grid import TrialGrid

__all__ = ["TrialFile"]


class TrialFile:
    """The writer of ``path`` for ``plan`` and the trials still to do (:attr:`todo`, in plan
    order). With ``resume`` an existing file is completed: ``check`` first sees its description
    (and raises if the file belongs to another plan), a file whose writer died is repaired
    (:attr:`repaired`: the recordings it kept). Without it an existing file is an error unless
    ``overwrite``. ``progress``: report progress over the whole plan (:class:`Progress`).

    The data set's lock (:mod:`aptkt.data.lock`) is taken before anything else and held until
    :meth:`close`: while another process writes the file, resuming, repairing and replacing
    it are all refused, naming that process."""

    def __init__(
        self,
        path: str | Path,
        plan: TrialGrid,
        *,
        description: Mapping[str, Any],
        resume: bool,
        overwrite: bool,
        check: Callable[[dict[str, Any]], None] | None = None,
        progress: bool = False,
    ):
        self.path = Path(path)
        self.plan = plan
        #: Recordings kept by repairing a file whose writer died (None: no repair).
        self.repaired: int | None = None
        self.lock = WriterLock.acquire(self.path)
        try:
            self.writer = self._writer(description, resume, overwrite, check)
        except BaseException:
            self.lock.release()
            raise
        done = self.writer.keys()
        self.todo: list[tuple[str, ExploratoryAction, int]] = [
            (o, a, t) for o, a, t in plan.trials() if (o, a.name, t) not in done
        ]
        self.bar = (
            Progress(len(plan), "trial", self.path.name, initial=len(plan) - len(self.todo))
            if progress
            else None
        )

    def _writer(
        self,
        description: Mapping[str, Any],
        resume: bool,
        overwrite: bool,
        check: Callable[[dict[str, Any]], None] | None,
    ) -> DatasetWriter:
        lock = self.lock
        if resume and self.path.exists():
            if check is not None:
                with DatasetReader(self.path) as rd:
                    check(rd.description)
            try:
                # (The description serves a file that holds nothing yet, started afresh.)
                return DatasetWriter(self.path, "a", description=description, lock=lock)
            except DatasetError:
                # Its writer died (no other runs: we hold the lock): keep every complete
                # recording.
                self.repaired = repair(self.path, lock=lock)
                return DatasetWriter(self.path, "a", lock=lock)
        if self.path.exists() and not overwrite:
            raise DatasetError(
                f"{self.path} exists: use --resume to complete it or --force to replace it"
            )
        return DatasetWriter(
            self.path, "w", description=description, overwrite=overwrite, lock=lock
        )

    def __enter__(self) -> TrialFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        try:
            if self.bar is not None:
                self.bar.close()
            self.writer.close()
        finally:
            self.lock.release()

    def summary(self, **extra: Any) -> dict[str, Any]:
        """The file's :meth:`~aptkt.data.DatasetReader.info`, whether it was repaired, and
        ``extra``; read after :meth:`close`."""
        with DatasetReader(self.path) as rd:
            info = rd.info()
        info.update(repaired=self.repaired, **extra)
        return info
