"""Where a dataset's stored bytes lie against the end of a file cut short.

HDF5's default file driver fills a read past the end of the file with zeros and reports no
error. Compressed data then fail to decompress (found), but uncompressed data — the index, or
feature matrices stored before checksums — came back as zeros: a truncated file's last features
were read as 0.0 and built into prior knowledge. So before such data are used, the position of
their bytes is compared with the file's size.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

__all__ = ["first_row_beyond", "file_size"]


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
