"""Data set files appear whole, and a file that holds nothing is known as such.

HDF5 writes a new file's 48-byte superblock the moment it creates it, and the file's structure
only when it is flushed: a writer killed in between (the first milliseconds) left a file that
nothing could open, and that ``--resume``, ``repair`` and a rerun all refused. So a data set
file is now built under a temporary name (``<name>.creating``) and renamed into place once its
structure is on disk: at its own name there is never less than an empty data set.

:func:`holds_nothing` recognises what such a kill left before this (an empty file, or a
superblock with nothing behind it): it cannot hold a recording, and the store treats it as an
empty data set (:func:`empty_data_set`) that an appending writer starts afresh.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from aptkt import __version__
from aptkt.data.codec import CHUNK_ROWS, COMPRESSION, META_CHUNK_BYTES, json_default
from aptkt.data.schema import INDEX_DTYPE, SAMPLE_FIELDS, SCHEMA, SCHEMA_VERSION
from aptkt.errors import DatasetError
from aptkt.files import not_a_regular_file, replaced_atomically

__all__ = [
    "CREATING_SUFFIX",
    "create",
    "create_data_set",
    "create_structure",
    "empty_data_set",
    "holds_nothing",
]

#: The suffix of a data set file while it is being created.
CREATING_SUFFIX = ".creating"

_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: Below this size a file cannot hold a recording: an aptkt data set's structure alone (its
#: datasets, created before the first recording) takes about 7 kB.
_SMALLER_THAN_ANY_DATA_SET = 4096


def create(path: Path, build: Callable[[Path], None]) -> None:
    """Create ``path`` by ``build(tmp)``, which writes and closes a complete file at ``tmp``
    (``<name>.creating``); it is synced and renamed onto ``path`` (replacing a file there) by
    :func:`aptkt.files.replaced_atomically`. A failure or a kill leaves ``path`` as it was;
    the next creation replaces a leftover ``tmp``."""
    with replaced_atomically(path, DatasetError, temp_suffix=CREATING_SUFFIX) as tmp:
        build(tmp)


def create_data_set(path: Path, description: Mapping[str, Any] | None) -> None:
    """Create ``path`` as an empty data set (see :func:`create_structure`), whole."""

    def build(tmp: Path) -> None:
        with h5py.File(tmp, "w", libver="latest", track_order=False) as f:
            create_structure(f, description)

    create(path, build)


def empty_data_set() -> h5py.File:
    """An empty data set in memory: what a file that :func:`holds_nothing` reads as."""
    f = h5py.File(io.BytesIO(), "w", libver="latest")
    create_structure(f, None)
    return f


def create_structure(f: h5py.File, description: Mapping[str, Any] | None) -> None:
    """An empty data set in ``f``: its attributes and every dataset, created before the first
    recording (SWMR mode creates no datasets)."""
    f.attrs["schema"] = SCHEMA
    f.attrs["schema_version"] = SCHEMA_VERSION
    f.attrs["software_version"] = __version__
    f.attrs["description"] = json.dumps(
        dict(description or {}), sort_keys=True, default=json_default
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
        chunks=(META_CHUNK_BYTES,),
        track_times=False,
        **COMPRESSION,
    )
    s = g.create_group("samples")
    for name, (tail, dtype) in SAMPLE_FIELDS.items():
        s.create_dataset(
            name,
            shape=(0, *tail),
            maxshape=(None, *tail),
            dtype=dtype,
            chunks=(CHUNK_ROWS, *tail),
            track_times=False,
            **COMPRESSION,
        )


def holds_nothing(path: str | Path) -> bool:
    """Whether ``path`` is a data set file that a writer killed as it created it left empty:
    no bytes, or an HDF5 file too small for any data set whose structure HDF5 cannot read (or
    that has none). Such a file holds no recording, so nothing is lost by starting it afresh.
    Any other file, HDF5 or not, is not such a file; nor is anything but a regular file (a
    device reads as empty too)."""
    if not_a_regular_file(path) is not None:
        return False
    try:
        size = os.path.getsize(path)
    except OSError:
        return False
    if size == 0:
        return True
    if size >= _SMALLER_THAN_ANY_DATA_SET:
        return False
    try:
        with open(path, "rb") as fh:
            if fh.read(len(_HDF5_SIGNATURE)) != _HDF5_SIGNATURE:
                return False
    except OSError:
        return False
    try:
        with h5py.File(path, "r") as f:
            return len(f) == 0 and len(f.attrs) == 0
    except (OSError, RuntimeError):  # (also a writer's mark: it died before any structure)
        return True
