"""Recordings (and optionally features) in HDF5: a versioned, compact, crash-safe store.

Layout: :mod:`aptkt.data.schema`. Samples are stored as the raw integers the skin sends (the
force before calibration, with the calibration kept in each recording's metadata), which is
exact, about a fifth of float64 and compresses well.

Crash safety: the writer runs in HDF5's single-writer/multiple-reader (SWMR) mode, in which
the library keeps each dataset's structure consistent on disk at every moment: every dataset
is created before the first recording, a recording is appended as samples → metadata → index
row, each on fresh chunks (no chunk holding an earlier recording is ever rewritten), and the
file is flushed after each one. Every recording whose append returned is therefore intact
whatever happens later. SWMR does not order the writes of *different* datasets during a
flush, so a writer killed mid-append can leave the new index row on disk before its samples or
metadata; the reader checks the last row against the other datasets and drops it if it is
incomplete (at most one append is ever in flight). :class:`DatasetReader` opens files in
SWMR-read mode, which also works while a writer is running or after it died. To *append* to a
file whose writer died, :func:`repair` first copies its complete recordings into a fresh file
(the HDF5 library refuses to reopen a crashed SWMR file for writing until that is done). A new
file is created whole, its structure built under another name first (:mod:`aptkt.data.atomic`).

Damage: HDF5 reads the bytes past the end of a file cut short as zeros, without an error, so the
reader checks the position of what it reads in such a file (:mod:`aptkt.data.integrity`);
compressed data (samples, metadata) carry zlib's checksum and stored features Fletcher-32, so
bytes changed on disk are an error when read. Every such error names the file and the
recording.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections import Counter
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from aptkt.data import atomic, integrity
from aptkt.data.codec import (
    CHUNK_ROWS,
    META_CHUNK_BYTES,
    PackedRecording,
    json_default,
    next_chunk_start,
    pack_raw,
    pack_recording,
    raw_to_samples,
    recording_key,
    samples_to_raw,
)
from aptkt.data.hdf5 import (
    copy_without_writer_mark,
    cut_short,
    open_swmr_read,
    readable_prefix,
    refused_for_writer_mark,
    while_locked,
)
from aptkt.data.lock import WriterLock, holder
from aptkt.data.schema import INDEX_DTYPE, READABLE_VERSIONS, SAMPLE_FIELDS, SCHEMA, SCHEMA_VERSION
from aptkt.errors import DatasetError, IndexOutOfRangeError, InvalidInputError, UnknownNameError
from aptkt.files import refuse_unless_regular, replaced_atomically
from aptkt.skin.samples import Recording

# DatasetError lives with the other errors; the codec's names are importable from here too.
__all__ = [
    "DatasetError",
    "DatasetWriter",
    "DatasetReader",
    "PackedRecording",
    "pack_recording",
    "repair",
    "recording_key",
    "samples_to_raw",
    "raw_to_samples",
]


class DatasetWriter:
    """Append recordings to a data set file, crash-safe (see the module docstring).

    ``mode="w"`` creates a new file (an existing one is an error unless ``overwrite``);
    ``mode="a"`` appends to an existing data set (create it if missing).

    The writer holds the data set's lock (:mod:`aptkt.data.lock`) until :meth:`close`: a
    second writer is refused, naming this one. ``lock``: the lock, taken already by the caller
    (who releases it), e.g. for a repair's copy of the file it holds.
    """

    def __init__(
        self,
        path: str | Path,
        mode: str = "w",
        *,
        description: Mapping[str, Any] | None = None,
        overwrite: bool = False,
        lock: WriterLock | None = None,
    ):

        self.path = Path(path)
        if mode not in ("w", "a"):
            raise InvalidInputError("mode must be 'w' or 'a'")
        self._own_lock = lock is None
        self.lock = WriterLock.acquire(self.path) if lock is None else lock
        try:
            self._open(mode, description, overwrite)
        except BaseException:
            self._release()
            raise

    def _open(self, mode: str, description: Mapping[str, Any] | None, overwrite: bool) -> None:
        if mode == "a" and atomic.holds_nothing(self.path):
            # Left by a writer killed as it created the file: nothing to append to.
            mode, overwrite = "w", True
        if mode == "a" and self.path.exists():
            self._f = self._open_for_appending()
        else:
            if self.path.exists() and not overwrite:
                raise DatasetError(f"{self.path} exists (use overwrite=True / --force, or append)")
            self._f = self._create(description)
        try:
            while_locked(self._start_swmr)
        except RuntimeError as exc:
            self._f.close()
            raise DatasetError(
                f"{self.path}: cannot start writing: another process keeps the file locked ({exc})"
            ) from exc
        # Handles are taken only now: a failed attempt to start SWMR writing invalidates the
        # handles open at the time, so a retry would leave the writer with dead ones.
        self._index = self._f["recordings/index"]
        self._meta = self._f["recordings/metadata"]
        self._samples = {name: self._f[f"recordings/samples/{name}"] for name in SAMPLE_FIELDS}
        self._keys = {
            (r["object"].decode(), r["action"].decode(), int(r["trial"])) for r in self._index[...]
        }

    def _open_for_appending(self) -> h5py.File:
        try:
            f = while_locked(lambda: h5py.File(self.path, "a", libver="latest"))
        except OSError as exc:
            if "already open" in str(exc) or "consistency flags" in str(exc):
                raise DatasetError(
                    f"{self.path}: a writer of this file did not close it (crashed or "
                    f"still running); run 'aptkt dataset repair {self.path}' first"
                ) from exc
            raise DatasetError(f"{self.path}: cannot open for appending: {exc}") from exc
        check_schema(f, self.path, for_writing=True)
        return f

    def _create(self, description: Mapping[str, Any] | None) -> h5py.File:
        """A new file with every dataset of the layout, empty; whole or not at all (a kill while
        HDF5 creates a file in place left 48 bytes nothing reads)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic.create_data_set(self.path, description)
        return while_locked(lambda: h5py.File(self.path, "a", libver="latest"))

    def _start_swmr(self) -> None:
        self._f.swmr_mode = True

    def __enter__(self) -> DatasetWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __len__(self) -> int:
        return int(self._index.shape[0])

    def keys(self) -> set[tuple[str, str, int]]:
        """``(object, action, trial)`` of every stored recording."""
        return set(self._keys)

    def append(self, rec: Recording) -> int:
        """Store one recording (flushed before returning); returns its number in the file."""
        return self.append_packed(pack_recording(rec))

    def _append_raw(
        self,
        key: tuple[str, str, int],
        start_ns: int,
        stop_ns: int,
        raw: Mapping[str, np.ndarray],
        meta_json: str,
    ) -> int:
        return self.append_packed(pack_raw(key, start_ns, stop_ns, raw, meta_json))

    def append_packed(self, rec: PackedRecording) -> int:
        """Store a packed recording (see :func:`pack_recording`); flushed before returning."""
        key = rec.key
        obj, action, trial = key
        if key in self._keys:
            raise DatasetError(f"{self.path}: {obj}/{action}/trial {trial} is already stored")
        n = rec.rows
        want = next_chunk_start(n, CHUNK_ROWS) // CHUNK_ROWS
        if any(len(rec.chunks.get(name, ())) != want for name in self._samples):
            raise InvalidInputError(f"packed recording {key}: expected {want} chunks per field")
        # Each recording starts on a fresh chunk of every dataset: chunks are then written once,
        # never rewritten by a later append — a rewritten compressed chunk moves, and a writer
        # killed before the move is on disk must not take an earlier recording with it. The
        # zero padding between recordings compresses to almost nothing; no index row points at it.
        row0 = next_chunk_start(self._samples["cell_id"].shape[0], CHUNK_ROWS)
        # Samples first, then the metadata, the index row last: the index defines what exists.
        for name, ds in self._samples.items():
            ds.resize(row0 + n, axis=0)
            for j, data in enumerate(rec.chunks[name]):
                offset = (row0 + j * CHUNK_ROWS,) + (0,) * (ds.ndim - 1)
                ds.id.write_direct_chunk(offset, data)
        meta_bytes = np.frombuffer(rec.meta_json.encode("utf-8"), dtype=np.uint8)
        meta0 = next_chunk_start(self._meta.shape[0], META_CHUNK_BYTES)
        self._meta.resize(meta0 + meta_bytes.size, axis=0)
        self._meta[meta0 : meta0 + meta_bytes.size] = meta_bytes
        i = len(self)
        row = np.array(
            [
                (
                    obj.encode(),
                    action.encode(),
                    trial,
                    rec.start_ns,
                    rec.stop_ns,
                    row0,
                    row0 + n,
                    meta0,
                    meta0 + meta_bytes.size,
                )
            ],
            dtype=INDEX_DTYPE,
        )
        self._index.resize(i + 1, axis=0)
        self._index[i : i + 1] = row
        self._f.flush()
        self._keys.add(key)
        return i

    def close(self) -> None:
        try:
            if getattr(self, "_f", None) is not None and self._f.id.valid:
                self._f.flush()
                self._f.close()
        finally:
            self._release()

    def _release(self) -> None:
        if self._own_lock:
            self.lock.release()


def check_schema(f: h5py.File, path: Path, *, for_writing: bool = False) -> int:
    """The file's schema version; a DatasetError if this aptkt cannot read (or append to) it."""
    schema = f.attrs.get("schema")
    version = f.attrs.get("schema_version")
    if isinstance(schema, bytes):
        schema = schema.decode()
    if schema != SCHEMA:
        raise DatasetError(f"{path}: not an aptkt data set (schema attribute {schema!r})")
    if version not in READABLE_VERSIONS:
        readable = ", ".join(map(str, READABLE_VERSIONS))
        raise DatasetError(
            f"{path}: schema version {version}, this aptkt reads versions {readable}"
        )
    if for_writing and version != SCHEMA_VERSION:
        raise DatasetError(
            f"{path}: schema version {version} is read-only for this aptkt; run "
            f"'aptkt dataset repair {path}' to rewrite it in version {SCHEMA_VERSION} first"
        )
    return int(version)


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


def repair(path: str | Path, *, backup: bool = True, lock: WriterLock | None = None) -> int:
    """Make a file whose writer died appendable again: copy every readable recording into a
    fresh file and put that in its place (the original is kept as ``<name>.crashed`` when
    ``backup``). Returns the number of recordings kept (:attr:`DatasetReader.damaged` tells
    which were not). Also rewrites a file of an older schema version in the current one. On
    any failure the file is left as it was and no temporary file remains.

    The data set's lock is held throughout (``lock``: the caller holds it already), so a file
    a live writer is writing is refused, naming that writer. Only regular files are renamed: a
    device, a FIFO or a directory at the file's name or at the backup's is refused."""
    path = Path(path)
    held = WriterLock.acquire(path) if lock is None else lock
    try:
        return _repair(path, backup, held)
    finally:
        if lock is None:
            held.release()


def _repair(path: Path, backup: bool, lock: WriterLock) -> int:
    crashed = path.with_name(path.name + ".crashed")
    if backup:
        refuse_unless_regular(crashed, DatasetError)
    with replaced_atomically(path, DatasetError, temp_suffix=".repairing") as tmp:
        with DatasetReader(path) as src:
            desc = src.description
            skip = set(src._implausible())
            # (The copy is under the original's lock: it is the original's next version.)
            with DatasetWriter(tmp, "w", description=desc, overwrite=True, lock=lock) as dst:
                n = 0
                for i in range(len(src)):
                    if i in skip:
                        continue
                    try:
                        meta = src.metadata(i)
                        raw = src.raw(i)
                    except (OSError, ValueError, DatasetError):  # damaged (past a truncation)
                        continue
                    r = src.index[i]
                    meta_json = json.dumps(meta, sort_keys=True, default=json_default)
                    dst._append_raw(
                        src.key(i), int(r["start_ns"]), int(r["stop_ns"]), raw, meta_json
                    )
                    n += 1
        if backup:  # (the copy is complete: the original steps aside just before it replaces it)
            os.replace(path, crashed)
    return n
