"""Reading a data set — also while its writer runs, or after it died — with every error naming
the file and the recording.

Files are opened in HDF5's SWMR-read mode, which also works while a writer appends
(:mod:`aptkt.data.writer`) or after one died in SWMR mode; a file whose writer died outside it
is read through a private copy without the writer's mark (:mod:`aptkt.data.hdf5`). At most one
append is ever in flight, and a writer killed mid-append can leave its index row on disk before
its samples or metadata, so the last row is checked against the other datasets and dropped if it
is incomplete.

Damage: HDF5 reads the bytes past the end of a file cut short as zeros, without an error, so the
reader checks the position of what it reads in such a file (:mod:`aptkt.data.integrity`);
compressed data (samples, metadata) carry zlib's checksum and stored features Fletcher-32, so
bytes changed on disk are an error when read.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from aptkt.data import atomic, integrity
from aptkt.data.codec import raw_to_samples
from aptkt.data.hdf5 import (
    copy_without_writer_mark,
    cut_short,
    open_swmr_read,
    readable_prefix,
    refused_for_writer_mark,
    while_locked,
)
from aptkt.data.lock import holder
from aptkt.data.schema import SAMPLE_FIELDS, check_schema
from aptkt.errors import DatasetError, IndexOutOfRangeError, UnknownNameError
from aptkt.files import refuse_unless_regular
from aptkt.skin.samples import Recording

__all__ = ["DatasetReader"]


class DatasetReader:
    """Read a data set (also while a writer runs, or after a writer died)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if not self.path.exists():
            raise DatasetError(f"{self.path}: no such file")
        refuse_unless_regular(self.path, DatasetError)
        #: The file's writer died outside SWMR mode: it is read through a private copy.
        self.writer_died = False
        #: The file holds nothing: its writer was killed as it created it (an aptkt that
        #: created files in place). Read as an empty data set; a writer starts it afresh.
        self.holds_nothing = atomic.holds_nothing(self.path)
        self._copy: Path | None = None
        self._damaged: list[int] | None = None
        if self.holds_nothing:
            self._f = atomic.empty_data_set()
        else:
            try:
                self._f = while_locked(lambda: open_swmr_read(self.path))
            except OSError as exc:
                if not refused_for_writer_mark(exc):
                    raise DatasetError(f"{self.path}: not a readable HDF5 data set: {exc}") from exc
                self._f = self._open_private_copy()
        #: The file is shorter than the end HDF5 recorded in it: bytes past its end read as
        #: zeros, so what lies there is checked before it is used.
        self.cut_short = cut_short(self.path)
        try:
            self.version = check_schema(self._f, self.path)
            self._meta = self._f["recordings/metadata"]
            self._samples = {name: self._f[f"recordings/samples/{name}"] for name in SAMPLE_FIELDS}
            # A snapshot: recordings appended after opening are not seen (reopen to see them).
            index = readable_prefix(self._f["recordings/index"])
            beyond = self._beyond(self._f["recordings/index"])
        except (OSError, KeyError, RuntimeError) as exc:  # HDF5: a checksum that never matched
            self.close()
            raise DatasetError(
                f"{self.path}: damaged: the file's structure cannot be read ({exc}); "
                "no recording can be recovered from it"
            ) from exc
        #: Index rows past the end of a file cut short (they read as zeros): recordings whose
        #: very names are lost, left out.
        self.lost = 0
        if beyond is not None and beyond < len(index):
            self.lost = len(index) - beyond
            index = index[:beyond]
        self.index = index[: self._complete(index)]
        #: Index rows of an append that was cut short (a writer killed mid-append, or one
        #: still running), left out: 0 or 1.
        # (A last index chunk past the end of the file is dropped by readable_prefix and not
        # counted: it can only hold that same in-flight row.)
        self.incomplete = len(index) - len(self.index)

    def _beyond(self, ds: h5py.Dataset) -> int | None:
        """The first row of ``ds`` past the end of this file, if it is cut short."""
        if not self.cut_short or self.holds_nothing:
            return None
        return integrity.first_row_beyond(ds, self.path.stat().st_size)

    def _open_private_copy(self) -> h5py.File:
        # (The name cut: a name near the file system's limit would not take the suffixes.)
        fd, name = tempfile.mkstemp(prefix=f"{self.path.name[:100]}.", suffix=".reading")
        os.close(fd)
        self._copy = Path(name)
        try:
            copy_without_writer_mark(self.path, self._copy)
            f = open_swmr_read(self._copy)
        except OSError as exc:
            self._copy.unlink(missing_ok=True)
            raise DatasetError(f"{self.path}: not a readable HDF5 data set: {exc}") from exc
        self.writer_died = True
        return f

    def _complete(self, index: np.ndarray) -> int:
        """How many leading rows of ``index`` are complete recordings. Only the last can be
        incomplete (appends are flushed one at a time), so only it is read back in full."""
        n = len(index)
        if n == 0:
            return 0
        last = index[n - 1]
        samples_end = min(ds.shape[0] for ds in self._samples.values())
        if not last["object"] or not 0 <= last["row_start"] <= last["row_stop"] <= samples_end:
            return n - 1
        if (
            self.version >= 2
            and not 0 <= last["meta_start"] < last["meta_stop"] <= self._meta.shape[0]
        ):
            return n - 1
        if self.version == 1 and self._meta.shape[0] < n:
            return n - 1
        try:
            self._read_metadata(last, n - 1)
            for ds in self._samples.values():
                ds[int(last["row_start"]) : int(last["row_stop"])]
        except (OSError, ValueError, DatasetError):  # past the end of the file, or torn
            return n - 1
        return n

    def _read_metadata(self, row: np.void, i: int) -> dict[str, Any]:
        if self.version >= 2:
            raw = self._meta[int(row["meta_start"]) : int(row["meta_stop"])].tobytes()
        else:
            raw = self._meta[i]
        return integrity.parse_metadata(raw, self.path, i, row)

    def __enter__(self) -> DatasetReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._f.id.valid:
            self._f.close()
        if self._copy is not None:
            self._copy.unlink(missing_ok=True)
            self._copy = None

    def __len__(self) -> int:
        return int(self.index.shape[0])

    @property
    def description(self) -> dict[str, Any]:
        return json.loads(self._f.attrs.get("description", "{}"))

    @property
    def attrs(self) -> dict[str, Any]:
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in self._f.attrs.items()}

    def key(self, i: int) -> tuple[str, str, int]:
        r = self.index[i]
        # (errors="replace": a damaged row must still be nameable in the error that names it.)
        return (
            r["object"].decode("utf-8", errors="replace"),
            r["action"].decode("utf-8", errors="replace"),
            int(r["trial"]),
        )

    def keys(self) -> list[tuple[str, str, int]]:
        return [self.key(i) for i in range(len(self))]

    def select(self, *, object: str | None = None, action: str | None = None) -> list[int]:  # noqa: A002
        """Recording numbers matching an object and/or action name."""
        out = []
        for i in range(len(self)):
            o, a, _ = self.key(i)
            if (object is None or o == object) and (action is None or a == action):
                out.append(i)
        return out

    def metadata(self, i: int) -> dict[str, Any]:
        if not (0 <= i < len(self)):
            raise IndexOutOfRangeError(f"recording {i} out of range (0..{len(self) - 1})")
        return self._read_metadata(self.index[i], i)

    def raw(self, i: int) -> dict[str, np.ndarray]:
        """The stored raw integers of recording ``i``."""
        if not (0 <= i < len(self)):
            raise IndexOutOfRangeError(f"recording {i} out of range (0..{len(self) - 1})")
        r = self.index[i]
        sl = slice(int(r["row_start"]), int(r["row_stop"]))
        return {name: ds[sl] for name, ds in self._samples.items()}

    def recording(self, i: int) -> Recording:
        meta = self.metadata(i)
        r = self.index[i]
        return Recording(
            samples=raw_to_samples(self.raw(i), meta),
            start_ns=int(r["start_ns"]),
            stop_ns=int(r["stop_ns"]),
            cells=tuple(int(c) for c in meta.get("cells", ())),
            silent_cells=tuple(int(c) for c in meta.get("silent_cells", ())),
            metadata=meta,
        )

    def __iter__(self) -> Iterator[Recording]:
        for i in range(len(self)):
            yield self.recording(i)

    def features(self, action: str, modality: str) -> tuple[np.ndarray, np.ndarray]:
        """``(recording numbers, values)`` of stored features; KeyError if there are none,
        :class:`DatasetError` naming the recording if they are damaged (past the end of a file
        cut short, or failing their checksum)."""
        try:
            g = self._f.get(f"features/{action}")
            stored = g is not None and modality in g
        except (KeyError, OSError) as exc:  # a group header past the end of the file
            raise DatasetError(
                f"{self.path}: the stored features of {action} are damaged (their structure "
                f"cannot be read: {exc}); run 'aptkt dataset repair {self.path}', then "
                "extract the features again"
            ) from None
        if not stored:
            raise UnknownNameError(f"no stored {modality!r} features for action {action!r}")
        problem = self._feature_damage(action, modality, read=True)
        if problem is not None:
            raise DatasetError(
                f"{self.path}: the stored {modality} features of {action} are damaged "
                f"({problem}); run 'aptkt dataset repair {self.path}' (it keeps the readable "
                "recordings, not the features), then extract the features again"
            )
        return g["recording"][...], g[modality][...]

    def _feature_damage(self, action: str, modality: str, *, read: bool) -> str | None:
        def name(i: int) -> str | None:
            return f"{i} ({integrity.row_name(self.index[i])})" if 0 <= i < len(self) else None

        return integrity.feature_damage(
            self._f, action, modality, beyond=self._beyond, recording_name=name, read=read
        )

    def damaged_features(self, *, full: bool = False) -> list[str]:
        """``action/modality: problem`` of every damaged stored feature matrix: those past the
        end of a file cut short; with ``full`` also those failing their checksum."""
        out = []
        for action, modalities in integrity.feature_groups(self._f).items():
            if modalities is None:
                out.append(f"{action}: their structure cannot be read: every {action} recording's")
            for m in modalities or ():
                problem = self._feature_damage(action, m, read=full)
                if problem is not None:
                    out.append(f"{action}/{m}: {problem}")
        return out

    def feature_settings(self, action: str) -> dict[str, Any] | None:
        """The extraction settings the stored features of ``action`` were computed with (None
        if there are none, or they were stored without)."""
        g = self._f.get(f"features/{action}")
        if g is None or "extraction" not in g.attrs:
            return None
        settings: dict[str, Any] = json.loads(g.attrs["extraction"])
        return settings

    def feature_names(self) -> dict[str, list[str]]:
        """Stored modalities by action (none for an action whose group cannot be read: see
        :meth:`damaged_features`)."""
        return {a: m or [] for a, m in integrity.feature_groups(self._f).items()}

    def damaged(self, *, full: bool = False) -> list[int]:
        """Numbers of the indexed recordings whose samples or metadata cannot be read (their
        compression's checksum fails, their metadata is not JSON) or whose index row is
        impossible. Every recording is read once to find out — only when the file is shorter
        than HDF5 recorded (cut short) or its writer died, unless ``full`` (a file damaged in
        its middle on disk is then found too; it costs about 8 ms per recording)."""
        implausible = self._implausible()
        if not (full or self.writer_died or self.cut_short):
            return implausible
        if self._damaged is None:
            bad = set(implausible)
            for i in range(len(self)):
                if i in bad:
                    continue
                try:
                    self.metadata(i)
                    self.raw(i)
                except (OSError, ValueError, DatasetError):
                    bad.add(i)
            self._damaged = sorted(bad)
        return list(self._damaged)

    def _implausible(self) -> list[int]:
        return integrity.implausible_rows(self.index, self._samples, self._meta, self.version)

    def damage(self, *, full: bool = False) -> str | None:
        """The damage found (see :meth:`damaged`, :meth:`damaged_features`), in one phrase
        naming the first damaged recording; None if none is found."""
        bad = self.damaged(full=full)
        first = integrity.row_name(self.index[bad[0]]) if bad else None
        return integrity.damage_phrase(self.lost, bad, first, self.damaged_features(full=full))

    def info(self, *, full: bool = False) -> dict[str, Any]:
        """A summary of the readable recordings: counts per object and action, samples, size on
        disk, schema; ``damaged`` lists ``object/action/trial`` of those that are not,
        ``damaged_features`` the stored features that are not, ``lost`` counts index rows past
        the end of a file cut short, ``writer`` records the process writing the file now
        (:func:`aptkt.data.lock.holder`). ``full``: read everything to find damage (see
        :meth:`damaged`)."""
        damaged = self.damaged(full=full)
        index = np.delete(self.index, damaged)
        objects = Counter(index["object"].astype(str).tolist())
        actions = Counter(index["action"].astype(str).tolist())
        rows = int(np.sum(index["row_stop"] - index["row_start"])) if len(index) else 0
        durations = (index["stop_ns"] - index["start_ns"]) * 1e-9
        return {
            "path": str(self.path),
            "schema": f"{self.attrs.get('schema')} v{self.attrs.get('schema_version')}",
            "software_version": self.attrs.get("software_version"),
            "recordings": len(index),
            "damaged": ["{}/{}/trial {}".format(*self.key(i)) for i in damaged],
            "damaged_features": self.damaged_features(full=full),
            "lost": self.lost,
            "holds_nothing": self.holds_nothing,
            "writer_died": self.writer_died,
            "writer": holder(self.path),
            "incomplete": self.incomplete,
            "objects": dict(objects),
            "actions": dict(actions),
            "samples": rows,
            "recorded_seconds": float(durations.sum()) if len(index) else 0.0,
            "file_bytes": self.path.stat().st_size,
            "bytes_per_sample": self.path.stat().st_size / rows if rows else float("nan"),
            "features": self.feature_names(),
            "description": self.description,
        }
