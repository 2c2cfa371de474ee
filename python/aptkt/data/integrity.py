"""Damage in a data set file, found before it is used: where its stored bytes lie against the
end of a file cut short, index rows no writer writes, metadata that is not JSON, and stored
features past the end or failing their checksum.

HDF5's default file driver fills a read past the end of the file with zeros and reports no
error. Compressed data then fail to decompress (found), but uncompressed data — the index, or
feature matrices stored before checksums — came back as zeros: a truncated file's last features
were read as 0.0 and built into prior knowledge. So before such data are used, the position of
their bytes is compared with the file's size. The reader (:class:`~aptkt.data.DatasetReader`)
asks these functions; each phrase they return names the recording or the features it found
damaged.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from aptkt.errors import DatasetError

__all__ = [
    "damage_phrase",
    "feature_damage",
    "feature_groups",
    "file_size",
    "first_row_beyond",
    "implausible_rows",
    "parse_metadata",
    "row_name",
]


def file_size(path: str | Path) -> int:
    return os.path.getsize(path)


def first_row_beyond(ds: h5py.Dataset, size: int) -> int | None:
    """The first row (along axis 0) of ``ds`` whose bytes lie, wholly or in part, beyond
    ``size`` bytes from the start of the file; None if every stored byte lies before it.
    Rows never written (chunks not allocated) read as the fill value by design, not as damage.
    """
    dsid = ds.id
    if ds.chunks is None:
        offset = dsid.get_offset()
        if offset is None or ds.shape[0] == 0:
            return None
        if offset + dsid.get_storage_size() <= size:
            return None
        row_bytes = ds.dtype.itemsize * int(np.prod(ds.shape[1:], dtype=np.int64))
        return int(max(0, (size - offset) // max(row_bytes, 1)))
    first = None
    for i in range(dsid.get_num_chunks()):
        info = dsid.get_chunk_info(i)
        if info.byte_offset is None or info.byte_offset + info.size <= size:
            continue
        row = int(info.chunk_offset[0])
        first = row if first is None else min(first, row)
    return first


def row_name(row: np.void) -> str:
    """``object/action/trial n`` of an index row (a damaged row's bytes replaced: it must still
    be nameable in the error that names it)."""

    def text(b: bytes) -> str:
        return b.decode("utf-8", errors="replace")

    return f"{text(row['object'])}/{text(row['action'])}/trial {int(row['trial'])}"


def parse_metadata(raw: Any, path: Path, i: int, row: np.void) -> dict[str, Any]:
    """Recording ``i``'s metadata from its stored JSON; bytes that are not a JSON object (changed
    on disk) are a :class:`DatasetError` naming the recording."""
    try:
        meta = json.loads(raw.decode("utf-8") if isinstance(raw, bytes) else raw)
    except ValueError as exc:  # not UTF-8, or not JSON: bytes changed on disk
        raise DatasetError(
            f"{path}: recording {i} ({row_name(row)}) is damaged: its metadata is not valid "
            f"JSON ({exc}); 'aptkt dataset repair {path}' keeps the readable recordings"
        ) from None
    if not isinstance(meta, dict):
        raise DatasetError(
            f"{path}: recording {i} ({row_name(row)}) is damaged: its metadata is not a JSON "
            f"object; 'aptkt dataset repair {path}' keeps the readable ones"
        )
    return meta


def implausible_rows(
    index: np.ndarray, samples: Mapping[str, h5py.Dataset], meta: h5py.Dataset, version: int
) -> list[int]:
    """Index rows no writer writes: an empty name, or sample or metadata ranges outside their
    datasets (zeros or changed bytes; the index has no checksum of its own). A vectorised look
    at the index: cheap enough to do always."""
    if len(index) == 0:
        return []
    samples_end = min(ds.shape[0] for ds in samples.values())
    bad = (index["object"] == b"") | (index["action"] == b"")
    bad |= (index["row_start"] < 0) | (index["row_start"] > index["row_stop"])
    bad |= index["row_stop"] > samples_end
    if version >= 2:
        bad |= (index["meta_start"] < 0) | (index["meta_start"] >= index["meta_stop"])
        bad |= index["meta_stop"] > meta.shape[0]
    return [int(i) for i in np.flatnonzero(bad)]


def feature_groups(f: h5py.File) -> dict[str, list[str] | None]:
    """Stored modalities by action; None for an action whose group cannot be read (its header
    past the end of a file cut short)."""
    try:
        g = f.get("features")
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


def feature_damage(
    f: h5py.File,
    action: str,
    modality: str,
    *,
    beyond: Callable[[h5py.Dataset], int | None],
    recording_name: Callable[[int], str | None],
    read: bool,
) -> str | None:
    """What is wrong with the stored features of ``action`` / ``modality`` (None: nothing
    found). Their position against the end of the file (``beyond``: the first row of a dataset
    past it, None if none) is always checked; with ``read`` they are read too (checksums, when
    they were stored with them). ``recording_name``: ``i (object/action/trial n)`` of a
    recording number, None if there is no such recording."""
    every = f"those of every {action} recording"
    try:
        g = f[f"features/{action}"]
        recs, values = g["recording"], g[modality]
    except (KeyError, OSError) as exc:  # a header past the end of the file, or changed
        return f"their structure cannot be read ({exc}): {every}"
    try:
        for ds in (recs, values):
            row = beyond(ds)
            if row is not None:
                where = f"from row {row} on"
                if ds is values and beyond(recs) is None:
                    name = recording_name(int(recs[row]))
                    if name is not None:
                        where = f"from recording {name} on"
                elif ds is recs:
                    where = every
                return f"the file ends before them: {where}"
        if read:
            recs[...]
            values[...]
    except (OSError, ValueError, IndexError) as exc:  # a checksum, or an unreadable chunk
        return f"they cannot be read ({exc}): {every}"
    return None


def damage_phrase(
    lost: int, bad: list[int], first_name: str | None, feature_problems: list[str]
) -> str | None:
    """The damage found, in one phrase naming the first damaged recording (``bad``: the damaged
    recordings' numbers, ``first_name`` the first one's name; ``lost``: index rows past the end
    of the file); None if there is none."""
    problems = []
    if lost:
        problems.append(f"{lost} recording(s) indexed past the end of the file (their names lost)")
    if bad:
        more = f" and {len(bad) - 1} more" if len(bad) > 1 else ""
        problems.append(f"recording {bad[0]} ({first_name}){more} cannot be read")
    problems += [f"stored features {p}" for p in feature_problems]
    return "; ".join(problems) if problems else None
