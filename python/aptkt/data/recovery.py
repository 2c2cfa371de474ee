"""Making a data set whose writer died appendable again, or one of an older schema version
current.

The HDF5 library refuses to reopen a crashed SWMR file for writing, and a version 1 file is
never appended to (:mod:`aptkt.data.schema`), so such a file is not mended in place: what the
reader can read of it (:mod:`aptkt.data.reader`) is copied into a fresh file
(:mod:`aptkt.data.writer`) that replaces it whole.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from aptkt.data.codec import json_default
from aptkt.data.lock import WriterLock
from aptkt.data.reader import DatasetReader
from aptkt.data.writer import DatasetWriter
from aptkt.errors import DatasetError
from aptkt.files import refuse_unless_regular, replaced_atomically

__all__ = ["repair"]


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
