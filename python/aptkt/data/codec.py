"""Recordings as the store holds them: the raw integers of the wire (exact, with the force
calibration in the metadata), the metadata as JSON, and the compressed HDF5 chunks the writer
places as they are (:class:`PackedRecording`)."""

from __future__ import annotations

import json
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt.data.schema import SAMPLE_FIELDS
from aptkt.errors import InvalidInputError
from aptkt.skin.config import ForceCalibration
from aptkt.skin.protocol import RAW_FIELDS, quantize, to_physical
from aptkt.skin.samples import Recording, SkinSamples

__all__ = [
    "CHUNK_ROWS",
    "META_CHUNK_BYTES",
    "COMPRESSION",
    "PackedRecording",
    "next_chunk_start",
    "pack_raw",
    "pack_recording",
    "raw_to_samples",
    "recording_key",
    "samples_to_raw",
    "json_default",
]

CHUNK_ROWS = 16384
META_CHUNK_BYTES = 4096  # a recording's metadata is ≈ 3 KB of JSON
#: Level 1: the samples are small integers after the byte shuffle; higher levels cost several
#: times the CPU for a few percent of file size.
_GZIP_LEVEL = 1
COMPRESSION = {"compression": "gzip", "compression_opts": _GZIP_LEVEL, "shuffle": True}


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
        raise InvalidInputError(
            "recording metadata needs 'object' (str), 'action' (name or dict with 'name') and 'trial' (int)"
        )
    return meta["object"], name, int(meta["trial"])


def json_default(obj: Any) -> Any:
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (tuple, set)):
        return list(obj)
    raise TypeError(f"metadata value of type {type(obj).__name__} is not JSON-serialisable")


def _calibration_of(metadata: Mapping[str, Any]) -> ForceCalibration:
    try:
        return ForceCalibration.from_metadata(metadata.get("calibration"))
    except ValueError as exc:
        raise InvalidInputError(f"{exc} (needed to store and read raw forces)") from None


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
    # The core's quantiser (round half to even, clip to the field's range) maps the values onto
    # the grid, and its conversion back must give the values themselves: a value off the grid
    # or out of range is refused rather than stored as something else.
    try:
        raw = quantize(samples.cell_id, samples.proximity, samples.acc, samples.temp, force_norm)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{exc}; only skin data can be stored raw") from None
    for name in ("proximity", "acc", "temp"):
        off_grid = to_physical(name, raw[name]) != getattr(samples, name)
        if np.any(off_grid):
            bad = int(np.flatnonzero(off_grid.reshape(off_grid.shape[0], -1).any(axis=1))[0])
            raise InvalidInputError(
                f"{name}: values are not on the protocol's grid or outside its range (row {bad}); "
                "only skin data can be stored raw"
            )
    if cal is not None:
        # Calibration is float arithmetic in both directions: compare in newtons, to rounding.
        back = cal.to_newtons(samples.cell_id, to_physical("force", raw["force"]))
        if not np.allclose(back, samples.force, rtol=1e-9, atol=1e-12):
            raise InvalidInputError(
                "force: calibrated values do not come from 12-bit readings with this calibration"
            )
    out.update({name: raw[name].astype(fields[name]) for name in RAW_FIELDS})
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
    padded = np.zeros((next_chunk_start(n, CHUNK_ROWS), *tail), dtype=dtype)
    padded[:n] = values
    out = []
    for start in range(0, padded.shape[0], CHUNK_ROWS):
        block = padded[start : start + CHUNK_ROWS].reshape(-1).view(np.uint8)
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
        raise InvalidInputError("object names are limited to 64 bytes and action names to 32")
    n = int(np.asarray(raw["cell_id"]).shape[0])
    chunks = {}
    for name, (tail, dtype) in SAMPLE_FIELDS.items():
        values = np.asarray(raw[name])
        if values.shape != (n, *tail):
            raise InvalidInputError(f"{name}: expected shape {(n, *tail)}, got {values.shape}")
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
        json.dumps(meta, sort_keys=True, default=json_default),
    )


def next_chunk_start(length: int, chunk: int) -> int:
    return -(-int(length) // chunk) * chunk
