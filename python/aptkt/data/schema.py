"""The on-disk layout of aptkt data sets (HDF5), version 2.

::

    /                                attrs: schema = "aptkt.dataset", schema_version = 2,
                                            software_version, description (JSON)
    /recordings/index                (N,) compound: object, action, trial, start_ns, stop_ns,
                                            row_start, row_stop, meta_start, meta_stop — one
                                            row per recording
    /recordings/metadata             (B,) uint8  UTF-8 JSON of every recording (action
                                            parameters, trial, calibration, placement, ...),
                                            byte ranges from the index
    /recordings/samples/cell_id      (M,)   uint16   all samples of all recordings, row ranges
    /recordings/samples/t_ns         (M,)   int64    from the index; raw integers as the wire
    /recordings/samples/proximity    (M,)   uint16   carries them (physical = raw * scale +
    /recordings/samples/acc          (M, 3) int16    offset, see skin.SCALE), force before the
    /recordings/samples/temp         (M, 2) int16    per-cell calibration (stored in each
    /recordings/samples/force        (M, 3) uint16   recording's metadata)
    /features/<action>/<modality>    (K, D) float64  optional, rows of recordings ...
    /features/<action>/recording     (K,)   int64    ... given by these recording numbers

A recording exists once its index row exists: samples and metadata are written first, the
index row last, then the file is flushed. Every recording's samples and metadata start on a
fresh chunk, so appending never rewrites a chunk that holds an earlier recording.

Version 1 stored the metadata as variable-length strings, one per recording. Those live in
HDF5's global heap, which single-writer/multiple-reader mode does not protect: a writer killed
mid-append could leave the heap extending past the end of the file. Version 1 files are still
read; ``aptkt dataset repair`` rewrites one in version 2 before anything is appended to it
(:func:`check_schema` refuses to append to it).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from aptkt.errors import DatasetError
from aptkt.skin.protocol import RAW_FIELDS

if TYPE_CHECKING:
    import h5py

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "READABLE_VERSIONS",
    "INDEX_DTYPE",
    "MAX_TRIAL_NUMBER",
    "SAMPLE_FIELDS",
    "check_schema",
]

SCHEMA = "aptkt.dataset"
SCHEMA_VERSION = 2
#: Versions this aptkt reads (it writes only SCHEMA_VERSION).
READABLE_VERSIONS = (1, 2)

INDEX_DTYPE = np.dtype(
    [
        ("object", "S64"),
        ("action", "S32"),
        ("trial", "<i4"),
        ("start_ns", "<i8"),
        ("stop_ns", "<i8"),
        ("row_start", "<i8"),
        ("row_stop", "<i8"),
        ("meta_start", "<i8"),
        ("meta_stop", "<i8"),
    ]
)
#: The largest trial number anywhere in aptkt: a data set's index stores it as a 32-bit integer,
#: and a feature table's trials become a data set's when exported back.
MAX_TRIAL_NUMBER = int(np.iinfo(INDEX_DTYPE["trial"]).max)

#: Stored per-sample fields: trailing shape and dtype. The skin's raw fields as the wire carries
#: them (:data:`aptkt.skin.protocol.RAW_FIELDS`, from the Rust crate), plus the host timestamp.
SAMPLE_FIELDS: dict[str, tuple[tuple[int, ...], np.dtype]] = {
    "cell_id": RAW_FIELDS["cell_id"],
    "t_ns": ((), np.dtype("<i8")),
    **{name: field for name, field in RAW_FIELDS.items() if name != "cell_id"},
}


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
