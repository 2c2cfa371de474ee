"""Appending recordings to a data set, crash-safe: every recording whose append returned is
intact whatever happens to the writer later.

The writer runs in HDF5's single-writer/multiple-reader (SWMR) mode, in which the library keeps
each dataset's structure consistent on disk at every moment: every dataset is created before the
first recording, a recording is appended as samples → metadata → index row, each on fresh chunks
(no chunk holding an earlier recording is ever rewritten), and the file is flushed after each
one. SWMR does not order the writes of *different* datasets during a flush, so a writer killed
mid-append can leave the new index row on disk before its samples or metadata; the reader drops
such a row (:mod:`aptkt.data.reader`). The HDF5 library refuses to reopen a crashed SWMR file
for writing, so a file whose writer died is appended to only after
:func:`~aptkt.data.recovery.repair`. A new file is created whole, its structure built under
another name first (:mod:`aptkt.data.atomic`).

Samples are stored as the raw integers the skin sends (the force before calibration, with the
calibration kept in each recording's metadata), which is exact, about a fifth of float64 and
compresses well (:mod:`aptkt.data.codec`; the layout: :mod:`aptkt.data.schema`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from aptkt.data import atomic
from aptkt.data.codec import (
    CHUNK_ROWS,
    META_CHUNK_BYTES,
    PackedRecording,
    next_chunk_start,
    pack_raw,
    pack_recording,
)
from aptkt.data.hdf5 import while_locked
from aptkt.data.lock import WriterLock
from aptkt.data.schema import INDEX_DTYPE, SAMPLE_FIELDS, check_schema
from aptkt.errors import DatasetError, InvalidInputError
from aptkt.files import present
from aptkt.skin.samples import Recording

__all__ = ["DatasetWriter"]


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
        if mode == "a" and self.path.is_symlink():
            # Appending opens the file in place: through a link it would write elsewhere.
            raise DatasetError(
                f"{self.path}: is a symbolic link; aptkt appends to no file through a link "
                "(give the file itself, or another name)"
            )
        if mode == "a" and atomic.holds_nothing(self.path):
            # Left by a writer killed as it created the file: nothing to append to.
            mode, overwrite = "w", True
        if mode == "a" and self.path.exists():
            self._f = self._open_for_appending()
        else:
            if present(self.path) and not overwrite:  # a dangling link too
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
