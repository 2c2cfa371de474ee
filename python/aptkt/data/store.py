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

import ctypes
import functools
import io
import json
import os
import shutil
import tempfile
import time
import zlib
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import h5py
import numpy as np

from aptkt import __version__
from aptkt.data import atomic
from aptkt.data.integrity import first_row_beyond
from aptkt.data.schema import (
    INDEX_DTYPE,
    READABLE_VERSIONS,
    SAMPLE_FIELDS,
    SCHEMA,
    SCHEMA_VERSION,
)
from aptkt.errors import AptktError
from aptkt.skin.config import ForceCalibration
from aptkt.skin.protocol import RAW_FIELDS, SCALE, to_physical
from aptkt.skin.samples import Recording, SkinSamples

__all__ = [
    "DatasetError",
    "DatasetWriter",
    "DatasetReader",
    "PackedRecording",
    "pack_recording",
    "repair",
    "write_features",
    "recording_key",
    "samples_to_raw",
    "raw_to_samples",
]

_CHUNK_ROWS = 16384
_META_CHUNK_BYTES = 4096  # a recording's metadata is ≈ 3 KB of JSON
#: Level 1: the samples are small integers after the byte shuffle; higher levels cost several
#: times the CPU for a few percent of file size.
_GZIP_LEVEL = 1
_COMPRESSION = {"compression": "gzip", "compression_opts": _GZIP_LEVEL, "shuffle": True}
_LOCK_PATIENCE_S = 2.0

_T = TypeVar("_T")


def _while_locked(step: Callable[[], _T]) -> _T:
    """Run an HDF5 open or create (or the switch to SWMR writing), retrying while another process
    holds the file's lock for a moment. A reader opening the file as the writer starts takes the lock
    briefly, and the writer's switch to SWMR mode would otherwise fail with errno 11 and end a
    collection before its first trial (measured: 3 of 60 starts with a reader polling)."""
    deadline = time.monotonic() + _LOCK_PATIENCE_S
    delay = 0.002
    while True:
        try:
            return step()
        except (OSError, RuntimeError) as exc:
            if "unable to lock file" not in str(exc) or time.monotonic() > deadline:
                raise
        time.sleep(delay)
        delay = min(2 * delay, 0.05)


# A SWMR reader retries a metadata read whose checksum fails (the writer may be rewriting that
# block at this moment); HDF5's default of 100 attempts backs off exponentially, so on a file
# that is really damaged (truncated) a single read took minutes. A handful of quick attempts
# covers a block caught mid-write.
_SWMR_READ_ATTEMPTS = 12


@functools.cache
def _hdf5_library() -> ctypes.CDLL | None:
    """The HDF5 library h5py runs on (for the one setting h5py does not expose)."""
    candidates = sorted((Path(h5py.__file__).parent.parent / "h5py.libs").glob("libhdf5-*"))
    if not candidates:
        try:
            with open("/proc/self/maps") as fh:
                candidates = sorted(
                    {
                        Path(line.split()[-1])
                        for line in fh
                        if "/libhdf5." in line or "/libhdf5-" in line
                    }
                )
        except OSError:
            return None
    for lib in candidates:
        try:
            handle = ctypes.CDLL(str(lib))
            handle.H5Pset_metadata_read_attempts.argtypes = [ctypes.c_int64, ctypes.c_uint]
            return handle
        except (OSError, AttributeError):
            continue
    return None


def _open_swmr_read(path: Path) -> h5py.File:
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    lib = _hdf5_library()
    if lib is not None:
        lib.H5Pset_metadata_read_attempts(fapl.id, _SWMR_READ_ATTEMPTS)
    fid = h5py.h5f.open(os.fsencode(path), h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ, fapl=fapl)
    return h5py.File(fid)


# -- files whose writer died outside SWMR mode ---------------------------------------------------
# HDF5 marks a file "open for writing" in its superblock while a writer has it open. A writer in
# SWMR mode marks it "SWMR writing" too, and SWMR readers accept it even after that writer died.
# A writer killed *outside* SWMR mode (between opening a file and switching to SWMR, or any
# older aptkt writing features in place) leaves a mark every HDF5 open then refuses. What it
# wrote is intact: the reader works on a private copy whose mark is cleared (what HDF5's own
# h5clear does), never touching the file itself.

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _lookup3(data: bytes) -> int:
    """Bob Jenkins' lookup3 ``hashlittle`` with seed 0: HDF5's metadata checksum."""
    mask = 0xFFFFFFFF

    def rot(x: int, k: int) -> int:
        return ((x << k) | (x >> (32 - k))) & mask

    n = len(data)
    a = b = c = (0xDEADBEEF + n) & mask
    k = 0
    while n > 12:
        a = (a + int.from_bytes(data[k : k + 4], "little")) & mask
        b = (b + int.from_bytes(data[k + 4 : k + 8], "little")) & mask
        c = (c + int.from_bytes(data[k + 8 : k + 12], "little")) & mask
        a = (a - c) & mask ^ rot(c, 4)
        c = (c + b) & mask
        b = (b - a) & mask ^ rot(a, 6)
        a = (a + c) & mask
        c = (c - b) & mask ^ rot(b, 8)
        b = (b + a) & mask
        a = (a - c) & mask ^ rot(c, 16)
        c = (c + b) & mask
        b = (b - a) & mask ^ rot(a, 19)
        a = (a + c) & mask
        c = (c - b) & mask ^ rot(b, 4)
        b = (b + a) & mask
        n -= 12
        k += 12
    if n == 0:
        return c
    tail = data[k:] + bytes(12 - n)
    a = (a + int.from_bytes(tail[0:4], "little")) & mask
    b = (b + int.from_bytes(tail[4:8], "little")) & mask
    c = (c + int.from_bytes(tail[8:12], "little")) & mask
    c = (c ^ b) - rot(b, 14) & mask
    a = (a ^ c) - rot(c, 11) & mask
    b = (b ^ a) - rot(a, 25) & mask
    c = (c ^ b) - rot(b, 16) & mask
    a = (a ^ c) - rot(c, 4) & mask
    b = (b ^ a) - rot(a, 14) & mask
    c = (c ^ b) - rot(b, 24) & mask
    return c


def _superblock(fh: Any) -> tuple[int, bytearray] | None:
    """Offset and bytes of a version 2 or 3 superblock (the only ones with writer marks); HDF5
    looks for it at 0, 512, 1024, 2048, ..."""
    size = os.fstat(fh.fileno()).st_size
    offset = 0
    while offset + 12 <= size:
        fh.seek(offset)
        head = fh.read(12)
        if head[:8] == _HDF5_SIGNATURE:
            if head[8] not in (2, 3):
                return None
            fh.seek(offset)
            return offset, bytearray(fh.read(12 + 4 * head[9] + 4))
        offset = 512 if offset == 0 else 2 * offset
    return None


def _writer_mark(path: Path) -> int:
    """The superblock's file consistency flags (0: no writer has it open)."""
    try:
        with open(path, "rb") as fh:
            sb = _superblock(fh)
    except OSError:
        return 0
    return 0 if sb is None else sb[1][11]


def _cut_short(path: Path) -> bool:
    """Whether the file is shorter than the end its superblock records (truncated)."""
    try:
        with open(path, "rb") as fh:
            found = _superblock(fh)
            size = os.fstat(fh.fileno()).st_size
    except OSError:
        return False
    if found is None:
        return False
    sb, n = found[1], found[1][9]  # n: the size of a file address
    return size < found[0] + int.from_bytes(sb[12 + 2 * n : 12 + 3 * n], "little")


def _copy_without_writer_mark(path: Path, dest: Path) -> None:
    shutil.copyfile(path, dest)
    with open(dest, "r+b") as fh:
        found = _superblock(fh)
        if found is None:
            return
        offset, sb = found
        sb[11] = 0
        sb[-4:] = _lookup3(bytes(sb[:-4])).to_bytes(4, "little")
        fh.seek(offset)
        fh.write(sb)


def _refused_for_writer_mark(exc: BaseException) -> bool:
    text = str(exc)
    return "not already open for SWMR writing" in text or "already open for write" in text


class DatasetError(AptktError):
    """A data set file is missing, not an aptkt data set, of another schema version, or
    cannot be written (e.g. a writer died: run ``aptkt dataset repair``)."""


def recording_key(rec: Recording) -> tuple[str, str, int]:
    """``(object, action, trial)`` of a recording, from its metadata."""
    meta = rec.metadata
    action = meta.get("action")
    name = action.get("name") if isinstance(action, Mapping) else action
    if (
        not isinstance(meta.get("object"), str)
        or not isinstance(name, str)
        or not isinstance(meta.get("trial"), int)
    ):
        raise ValueError(
            "recording metadata needs 'object' (str), 'action' (name or dict with 'name') and 'trial' (int)"
        )
    return meta["object"], name, int(meta["trial"])


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (tuple, set)):
        return list(obj)
    raise TypeError(f"metadata value of type {type(obj).__name__} is not JSON-serialisable")


def _to_raw(name: str, values: np.ndarray, column: int = 0) -> np.ndarray:
    scale, offset = SCALE[name][column]
    raw = np.rint((values - offset) / scale)
    off_grid = (raw * scale + offset) != values
    if np.any(off_grid):
        bad = int(np.flatnonzero(off_grid.reshape(off_grid.shape[0], -1).any(axis=1))[0])
        raise ValueError(
            f"{name}: values are not on the protocol's grid (row {bad}); only skin data can be stored raw"
        )
    return raw


def _calibration_of(metadata: Mapping[str, Any]) -> ForceCalibration:
    try:
        return ForceCalibration.from_metadata(metadata.get("calibration"))
    except ValueError as exc:
        raise ValueError(f"{exc} (needed to store and read raw forces)") from None


def samples_to_raw(samples: SkinSamples, metadata: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """Samples → the stored columns: the raw integers of the wire.

    Samples that came off the wire keep those integers (``samples.raw``): they are stored as
    they are. Samples made otherwise are mapped back onto the wire's grid, exactly (raises if
    they are not on it).
    """
    fields = {name: dtype for name, (_, dtype) in SAMPLE_FIELDS.items()}
    out = {"t_ns": samples.t_ns.astype(fields["t_ns"])}
    if samples.raw is not None:
        out.update({name: col.astype(fields[name]) for name, col in samples.raw.items()})
        return {name: out[name] for name in SAMPLE_FIELDS}
    if len(samples):
        cal = _calibration_of(metadata)
        force_norm = cal.to_normalised(samples.cell_id, samples.force)
    else:
        cal, force_norm = None, np.zeros((0, 3))
    ((force_scale, _),) = SCALE["force"]
    force = np.rint(force_norm / force_scale)
    if cal is not None:
        back = cal.to_newtons(samples.cell_id, force * force_scale)
        if not np.allclose(back, samples.force, rtol=1e-9, atol=1e-12):
            raise ValueError(
                "force: calibrated values do not come from 12-bit readings with this calibration"
            )
    out.update(
        cell_id=samples.cell_id.astype(fields["cell_id"]),
        proximity=_to_raw("proximity", samples.proximity).astype(fields["proximity"]),
        acc=_to_raw("acc", samples.acc).astype(fields["acc"]),
        temp=np.stack(
            [_to_raw("temp", samples.temp[:, 0], 0), _to_raw("temp", samples.temp[:, 1], 1)], axis=1
        ).astype(fields["temp"]),
        force=force.astype(fields["force"]),
    )
    return {name: out[name] for name in SAMPLE_FIELDS}


def raw_to_samples(raw: Mapping[str, np.ndarray], metadata: Mapping[str, Any]) -> SkinSamples:
    """Stored raw integers → physical samples, with the same arithmetic as the skin sources
    (the integers stay with the samples, see :class:`~aptkt.skin.SkinSamples`)."""
    cells = np.asarray(raw["cell_id"], dtype=np.uint16)
    force_norm = to_physical("force", raw["force"])
    force = _calibration_of(metadata).to_newtons(cells, force_norm) if len(cells) else force_norm
    return SkinSamples(
        cell_id=cells,
        t_ns=np.asarray(raw["t_ns"], dtype=np.int64),
        proximity=to_physical("proximity", raw["proximity"]),
        acc=to_physical("acc", raw["acc"]),
        temp=to_physical("temp", raw["temp"]),
        force=force,
        raw={name: raw[name] for name in RAW_FIELDS},
    )


@dataclass(frozen=True)
class PackedRecording:
    """A recording as the writer stores it: its key, times, metadata JSON and, per sample field,
    the compressed HDF5 chunks of its raw integers (byte shuffle + deflate, exactly the
    datasets' filter pipeline), ready to be placed. Compact and cheap to pass between
    processes, so that data set generation compresses in its workers and the single writer
    only places chunks."""

    key: tuple[str, str, int]
    start_ns: int
    stop_ns: int
    rows: int
    meta_json: str
    chunks: dict[str, tuple[bytes, ...]]


def _compress_chunks(
    values: np.ndarray, tail: tuple[int, ...], dtype: np.dtype
) -> tuple[bytes, ...]:
    """The chunks of one field: rows padded with zeros to whole chunks, each chunk's bytes
    shuffled (byte j of every element together, as HDF5's shuffle filter) and deflated."""
    n = values.shape[0]
    padded = np.zeros((_next_chunk_start(n, _CHUNK_ROWS), *tail), dtype=dtype)
    padded[:n] = values
    out = []
    for start in range(0, padded.shape[0], _CHUNK_ROWS):
        block = padded[start : start + _CHUNK_ROWS].reshape(-1).view(np.uint8)
        shuffled = block.reshape(-1, dtype.itemsize).T.tobytes()
        out.append(zlib.compress(shuffled, _GZIP_LEVEL))
    return tuple(out)


def pack_raw(
    key: tuple[str, str, int],
    start_ns: int,
    stop_ns: int,
    raw: Mapping[str, np.ndarray],
    meta_json: str,
) -> PackedRecording:
    """Raw sample fields (see :data:`SAMPLE_FIELDS`) and metadata → a :class:`PackedRecording`."""
    obj, action, trial = key
    if len(obj.encode()) > 64 or len(action.encode()) > 32:
        raise ValueError("object names are limited to 64 bytes and action names to 32")
    n = int(np.asarray(raw["cell_id"]).shape[0])
    chunks = {}
    for name, (tail, dtype) in SAMPLE_FIELDS.items():
        values = np.asarray(raw[name])
        if values.shape != (n, *tail):
            raise ValueError(f"{name}: expected shape {(n, *tail)}, got {values.shape}")
        chunks[name] = _compress_chunks(values.astype(dtype, copy=False), tail, dtype)
    return PackedRecording(
        (str(obj), str(action), int(trial)), int(start_ns), int(stop_ns), n, meta_json, chunks
    )


def pack_recording(rec: Recording) -> PackedRecording:
    """A recording → a :class:`PackedRecording` (raw integers of the wire, exact)."""
    meta = dict(rec.metadata)
    meta.setdefault("cells", list(rec.cells))
    meta["silent_cells"] = list(rec.silent_cells)
    raw = samples_to_raw(rec.samples, meta)
    return pack_raw(
        recording_key(rec),
        rec.start_ns,
        rec.stop_ns,
        raw,
        json.dumps(meta, sort_keys=True, default=_json_default),
    )


class DatasetWriter:
    """Append recordings to a data set file, crash-safe (see the module docstring).

    ``mode="w"`` creates a new file (an existing one is an error unless ``overwrite``);
    ``mode="a"`` appends to an existing data set (create it if missing).
    """

    def __init__(
        self,
        path: str | Path,
        mode: str = "w",
        *,
        description: Mapping[str, Any] | None = None,
        overwrite: bool = False,
    ):

        self.path = Path(path)
        if mode not in ("w", "a"):
            raise ValueError("mode must be 'w' or 'a'")
        if mode == "a" and atomic.holds_nothing(self.path):
            # Left by a writer killed as it created the file: nothing to append to.
            mode, overwrite = "w", True
        if mode == "a" and self.path.exists():
            try:
                self._f = _while_locked(lambda: h5py.File(self.path, "a", libver="latest"))
            except OSError as exc:
                if "already open" in str(exc) or "consistency flags" in str(exc):
                    raise DatasetError(
                        f"{self.path}: a writer of this file did not close it (crashed or "
                        f"still running); run 'aptkt dataset repair {self.path}' first"
                    ) from exc
                raise DatasetError(f"{self.path}: cannot open for appending: {exc}") from exc
            _check_schema(self._f, self.path, for_writing=True)
        else:
            if self.path.exists() and not overwrite:
                raise DatasetError(
                    f"{self.path} exists (use overwrite=True / --overwrite, or append)"
                )
            self.path.parent.mkdir(parents=True, exist_ok=True)

            def build(tmp: Path) -> None:
                with h5py.File(tmp, "w", libver="latest", track_order=False) as f:
                    _create_structure(f, description)

            # Whole or not at all: a kill while HDF5 creates a file left 48 bytes nothing reads.
            atomic.create(self.path, build)
            self._f = _while_locked(lambda: h5py.File(self.path, "a", libver="latest"))
        try:
            _while_locked(self._start_swmr)
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
        want = _next_chunk_start(n, _CHUNK_ROWS) // _CHUNK_ROWS
        if any(len(rec.chunks.get(name, ())) != want for name in self._samples):
            raise ValueError(f"packed recording {key}: expected {want} chunks per field")
        # Each recording starts on a fresh chunk of every dataset: chunks are then written once,
        # never rewritten by a later append — a rewritten compressed chunk moves, and a writer
        # killed before the move is on disk must not take an earlier recording with it. The
        # zero padding between recordings compresses to almost nothing; no index row points at it.
        row0 = _next_chunk_start(self._samples["cell_id"].shape[0], _CHUNK_ROWS)
        # Samples first, then the metadata, the index row last: the index defines what exists.
        for name, ds in self._samples.items():
            ds.resize(row0 + n, axis=0)
            for j, data in enumerate(rec.chunks[name]):
                offset = (row0 + j * _CHUNK_ROWS,) + (0,) * (ds.ndim - 1)
                ds.id.write_direct_chunk(offset, data)
        meta_bytes = np.frombuffer(rec.meta_json.encode("utf-8"), dtype=np.uint8)
        meta0 = _next_chunk_start(self._meta.shape[0], _META_CHUNK_BYTES)
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
        if getattr(self, "_f", None) is not None and self._f.id.valid:
            self._f.flush()
            self._f.close()


def _create_structure(f: h5py.File, description: Mapping[str, Any] | None) -> None:
    """An empty data set in ``f``: its attributes and every dataset, created before the first
    recording (SWMR mode creates no datasets)."""
    f.attrs["schema"] = SCHEMA
    f.attrs["schema_version"] = SCHEMA_VERSION
    f.attrs["software_version"] = __version__
    f.attrs["description"] = json.dumps(
        dict(description or {}), sort_keys=True, default=_json_default
    )
    g = f.create_group("recordings")
    g.create_dataset(
        "index",
        shape=(0,),
        maxshape=(None,),
        dtype=INDEX_DTYPE,
        chunks=(256,),
        track_times=False,
    )
    g.create_dataset(
        "metadata",
        shape=(0,),
        maxshape=(None,),
        dtype=np.uint8,
        chunks=(_META_CHUNK_BYTES,),
        track_times=False,
        **_COMPRESSION,
    )
    s = g.create_group("samples")
    for name, (tail, dtype) in SAMPLE_FIELDS.items():
        s.create_dataset(
            name,
            shape=(0, *tail),
            maxshape=(None, *tail),
            dtype=dtype,
            chunks=(_CHUNK_ROWS, *tail),
            track_times=False,
            **_COMPRESSION,
        )


def _next_chunk_start(length: int, chunk: int) -> int:
    return -(-int(length) // chunk) * chunk


def _check_schema(f: h5py.File, path: Path, *, for_writing: bool = False) -> int:
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
        #: The file's writer died outside SWMR mode: it is read through a private copy.
        self.writer_died = False
        #: The file holds nothing: its writer was killed as it created it (an aptkt that
        #: created files in place). Read as an empty data set; a writer starts it afresh.
        self.holds_nothing = atomic.holds_nothing(self.path)
        self._copy: Path | None = None
        self._damaged: list[int] | None = None
        if self.holds_nothing:
            self._f = h5py.File(io.BytesIO(), "w", libver="latest")
            _create_structure(self._f, None)
        else:
            try:
                self._f = _while_locked(lambda: _open_swmr_read(self.path))
            except OSError as exc:
                if not _refused_for_writer_mark(exc):
                    raise DatasetError(f"{self.path}: not a readable HDF5 data set: {exc}") from exc
                self._f = self._open_private_copy()
        #: The file is shorter than the end HDF5 recorded in it: bytes past its end read as
        #: zeros, so what lies there is checked before it is used.
        self.cut_short = _cut_short(self.path)
        try:
            self.version = _check_schema(self._f, self.path)
            self._meta = self._f["recordings/metadata"]
            self._samples = {name: self._f[f"recordings/samples/{name}"] for name in SAMPLE_FIELDS}
            # A snapshot: recordings appended after opening are not seen (reopen to see them).
            index = _readable_prefix(self._f["recordings/index"])
            beyond = self._beyond(self._f["recordings/index"])
        except (OSError, KeyError) as exc:
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
        # (A last index chunk past the end of the file is dropped by _readable_prefix and not
        # counted: it can only hold that same in-flight row.)
        self.incomplete = len(index) - len(self.index)

    def _beyond(self, ds: h5py.Dataset) -> int | None:
        """The first row of ``ds`` past the end of this file, if it is cut short."""
        if not self.cut_short or self.holds_nothing:
            return None
        return first_row_beyond(ds, self.path.stat().st_size)

    def _open_private_copy(self) -> h5py.File:
        # (The name cut: a name near the file system's limit would not take the suffixes.)
        fd, name = tempfile.mkstemp(prefix=f"{self.path.name[:100]}.", suffix=".reading")
        os.close(fd)
        self._copy = Path(name)
        try:
            _copy_without_writer_mark(self.path, self._copy)
            f = _open_swmr_read(self._copy)
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
        try:
            meta = json.loads(raw.decode("utf-8") if isinstance(raw, bytes) else raw)
        except ValueError as exc:  # not UTF-8, or not JSON: bytes changed on disk
            raise DatasetError(
                f"{self.path}: recording {i} ({self._name(row)}) is damaged: its metadata is "
                f"not valid JSON ({exc}); 'aptkt dataset repair {self.path}' keeps the "
                "readable recordings"
            ) from None
        if not isinstance(meta, dict):
            raise DatasetError(
                f"{self.path}: recording {i} ({self._name(row)}) is damaged: its metadata is "
                f"not a JSON object; 'aptkt dataset repair {self.path}' keeps the readable ones"
            )
        return meta

    @staticmethod
    def _name(row: np.void) -> str:
        def text(b: bytes) -> str:
            return b.decode("utf-8", errors="replace")

        return f"{text(row['object'])}/{text(row['action'])}/trial {int(row['trial'])}"

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
            raise IndexError(f"recording {i} out of range (0..{len(self) - 1})")
        return self._read_metadata(self.index[i], i)

    def raw(self, i: int) -> dict[str, np.ndarray]:
        """The stored raw integers of recording ``i``."""
        if not (0 <= i < len(self)):
            raise IndexError(f"recording {i} out of range (0..{len(self) - 1})")
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
            raise KeyError(f"no stored {modality!r} features for action {action!r}")
        problem = self._feature_damage(action, modality, read=True)
        if problem is not None:
            raise DatasetError(
                f"{self.path}: the stored {modality} features of {action} are damaged "
                f"({problem}); run 'aptkt dataset repair {self.path}' (it keeps the readable "
                "recordings, not the features), then extract the features again"
            )
        return g["recording"][...], g[modality][...]

    def _feature_damage(self, action: str, modality: str, *, read: bool) -> str | None:
        """What is wrong with the stored features of ``action`` / ``modality`` (None: nothing
        found). Their position against the end of the file is always checked; with ``read``
        they are read too (checksums, when they were stored with them)."""
        every = f"those of every {action} recording"
        try:
            g = self._f[f"features/{action}"]
            recs, values = g["recording"], g[modality]
        except (KeyError, OSError) as exc:  # a header past the end of the file, or changed
            return f"their structure cannot be read ({exc}): {every}"
        try:
            for ds in (recs, values):
                row = self._beyond(ds)
                if row is not None:
                    where = f"from row {row} on"
                    if ds is values and self._beyond(recs) is None:
                        i = int(recs[row])
                        if 0 <= i < len(self):
                            where = f"from recording {i} ({self._name(self.index[i])}) on"
                    elif ds is recs:
                        where = every
                    return f"the file ends before them: {where}"
            if read:
                recs[...]
                values[...]
        except (OSError, ValueError, IndexError) as exc:  # a checksum, or an unreadable chunk
            return f"they cannot be read ({exc}): {every}"
        return None

    def damaged_features(self, *, full: bool = False) -> list[str]:
        """``action/modality: problem`` of every damaged stored feature matrix: those past the
        end of a file cut short; with ``full`` also those failing their checksum."""
        out = []
        for action, modalities in self._feature_groups().items():
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
        return {a: m or [] for a, m in self._feature_groups().items()}

    def _feature_groups(self) -> dict[str, list[str] | None]:
        """Stored modalities by action; None for an action whose group cannot be read (its
        header past the end of a file cut short)."""
        try:
            g = self._f.get("features")
            actions = [] if g is None else list(g)
        except (KeyError, OSError):
            return {"(every action)": None}
        out: dict[str, list[str] | None] = {}
        for a in actions:
            try:
                out[a] = sorted(k for k in g[a] if k != "recording")
            except (KeyError, OSError):
                out[a] = None
        return out

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
        """Index rows no writer writes: an empty name, or sample or metadata ranges outside
        their datasets (zeros or changed bytes; the index has no checksum of its own). A
        vectorised look at the index: always done."""
        ix = self.index
        if len(ix) == 0:
            return []
        samples_end = min(ds.shape[0] for ds in self._samples.values())
        bad = (ix["object"] == b"") | (ix["action"] == b"")
        bad |= (ix["row_start"] < 0) | (ix["row_start"] > ix["row_stop"])
        bad |= ix["row_stop"] > samples_end
        if self.version >= 2:
            bad |= (ix["meta_start"] < 0) | (ix["meta_start"] >= ix["meta_stop"])
            bad |= ix["meta_stop"] > self._meta.shape[0]
        return [int(i) for i in np.flatnonzero(bad)]

    def damage(self, *, full: bool = False) -> str | None:
        """The damage found (see :meth:`damaged`, :meth:`damaged_features`), in one phrase
        naming the first damaged recording; None if none is found."""
        problems = []
        if self.lost:
            problems.append(
                f"{self.lost} recording(s) indexed past the end of the file (their names lost)"
            )
        bad = self.damaged(full=full)
        if bad:
            more = f" and {len(bad) - 1} more" if len(bad) > 1 else ""
            problems.append(
                f"recording {bad[0]} ({self._name(self.index[bad[0]])}){more} cannot be read"
            )
        problems += [f"stored features {p}" for p in self.damaged_features(full=full)]
        return "; ".join(problems) if problems else None

    def info(self, *, full: bool = False) -> dict[str, Any]:
        """A summary of the readable recordings: counts per object and action, samples, size on
        disk, schema; ``damaged`` lists ``object/action/trial`` of those that are not,
        ``damaged_features`` the stored features that are not, ``lost`` counts index rows past
        the end of a file cut short. ``full``: read everything to find damage (see
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


def write_features(
    path: str | Path,
    action: str,
    modality: str,
    recordings: Sequence[int],
    values: np.ndarray,
    *,
    settings: Mapping[str, Any] | None = None,
) -> None:
    """Store a feature matrix (one row per recording number) under ``/features/<action>``
    (see :func:`store_features`)."""
    store_features(path, {action: (recordings, {modality: values})}, settings=settings)


def store_features(
    path: str | Path,
    features: Mapping[str, tuple[Sequence[int], Mapping[str, np.ndarray]]],
    *,
    settings: Mapping[str, Any] | None = None,
) -> None:
    """Store feature matrices: ``{action: (recording numbers, {modality: values})}``, keyed by
    the extraction ``settings`` they were computed with (JSON, see
    :meth:`DatasetReader.feature_settings`; None: unknown settings).

    The file is never modified in place: the features are written into a copy that then
    replaces it (a rename), so a kill at any moment leaves the file as it was, or with all the
    features. No writer may be running (the copy would miss its later appends)."""
    path = Path(path)
    checked = {}
    for action, (recordings, mods) in features.items():
        recs = np.asarray(recordings, dtype=np.int64)
        vals = {m: np.asarray(v, dtype=np.float64) for m, v in mods.items()}
        for v in vals.values():
            if v.ndim != 2 or v.shape[0] != recs.shape[0]:
                raise ValueError(
                    "values must be (n_recordings, dim) with one row per recording number"
                )
        checked[action] = (recs, vals)
    if _writer_mark(path):
        raise DatasetError(
            f"{path}: a writer has the file open, or died without closing it; wait for it to "
            f"finish, or run 'aptkt dataset repair {path}' first"
        )
    if _cut_short(path):
        raise DatasetError(
            f"{path}: the file is cut short (it ends before the end HDF5 recorded in it): "
            f"features cannot be stored in it; run 'aptkt dataset repair {path}' first (it "
            "keeps every readable recording)"
        )
    tmp = path.with_name(path.name + ".features-tmp")
    try:
        shutil.copyfile(path, tmp)
        with h5py.File(tmp, "a", libver="latest") as f:
            _check_schema(f, path)
            n = f["recordings/index"].shape[0]
            for action, (recs, vals) in checked.items():
                if recs.size and (recs.min() < 0 or recs.max() >= n):
                    raise ValueError(f"recording numbers must be in 0..{n - 1}")
                g = f.require_group(f"features/{action}")
                if "recording" in g and not np.array_equal(g["recording"][...], recs):
                    if not set(vals) >= set(g) - {"recording"}:
                        raise ValueError(
                            f"features of {action!r} exist for other recordings; write all "
                            "modalities together"
                        )
                    del g["recording"]
                    for m in [k for k in g if k != "recording"]:
                        del g[m]
                # Fletcher-32: a changed byte is an error when read, not another number.
                if "recording" not in g:
                    g.create_dataset("recording", data=recs, track_times=False, fletcher32=True)
                for modality, values in vals.items():
                    if modality in g:
                        del g[modality]
                    g.create_dataset(modality, data=values, track_times=False, fletcher32=True)
                if settings is None:
                    g.attrs.pop("extraction", None)
                else:
                    g.attrs["extraction"] = json.dumps(dict(settings), sort_keys=True)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _readable_prefix(ds: h5py.Dataset) -> np.ndarray:
    """All of a dataset, or, when its last chunk lies past the end of a file whose writer was
    killed (that chunk belongs to the append in flight), everything before that chunk."""
    try:
        return ds[...]
    except OSError:
        chunk = ds.chunks[0] if ds.chunks else 1
        return ds[: max(0, (ds.shape[0] - 1) // chunk * chunk)]


def repair(path: str | Path, *, backup: bool = True) -> int:
    """Make a file whose writer died appendable again: copy every readable recording into a
    fresh file and put that in its place (the original is kept as ``<name>.crashed`` when
    ``backup``). Returns the number of recordings kept (:attr:`DatasetReader.damaged` tells
    which were not). Also rewrites a file of an older schema version in the current one. On
    any failure the file is left as it was and no temporary file remains."""
    path = Path(path)
    tmp = path.with_name(path.name + ".repairing")
    try:
        with DatasetReader(path) as src:
            desc = src.description
            skip = set(src._implausible())
            with DatasetWriter(tmp, "w", description=desc, overwrite=True) as dst:
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
                    meta_json = json.dumps(meta, sort_keys=True, default=_json_default)
                    dst._append_raw(
                        src.key(i), int(r["start_ns"]), int(r["stop_ns"]), raw, meta_json
                    )
                    n += 1
        if backup:
            os.replace(path, path.with_name(path.name + ".crashed"))
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return n
