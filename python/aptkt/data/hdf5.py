"""HDF5 below h5py: what the crash-safe store needs of the library and of the file format.

Retries while another process holds a file's lock for a moment; SWMR reads with few metadata
retries (a setting h5py does not expose, set through ctypes); and the superblock's writer mark
— HDF5's "open for writing" flags, their lookup3 checksum, and whether a file was cut short —
so that a file whose writer died outside SWMR mode can be read through a private copy.

Why not h5py's own options: measured with h5py 3.16.0 on its bundled HDF5 2.0.0 (files as the
store writes them, writers ended by ``os._exit`` or SIGKILL), and read in HDF5's source.

- *Metadata read attempts.* h5py has no way to set them: no ``PropFAID`` method, no
  ``h5py.File`` keyword (none in h5py's development tree either), though the library exports
  ``H5Pset_metadata_read_attempts``. A SWMR reader retries a metadata block whose checksum fails
  up to that many times, sleeping 1 ns, then twice as long each time (``H5C__load_entry``,
  src/H5Centry.c): HDF5's SWMR default of 100 attempts sleeps 2**99 ns in all, so one read of
  a damaged block never returns (measured: none returned within 120 s; 30 attempts: 1.1 s;
  12 attempts: under 10 ms). SWMR reading itself cannot be dropped: it reads files a live or
  dead SWMR writer holds, and files cut short (a non-SWMR open refuses those: "truncated
  file"). So the setting stays, set through the library h5py runs on, found through h5py's
  own extension module whatever that library's file is named (:func:`_hdf5_library`; a test
  fails if it is not found, or if h5py starts to expose the setting).
- *The writer mark.* HDF5 checks a file's consistency flags as it opens it, for a version 3
  superblock only (``H5F_open``, src/H5Fint.c), and whatever the file locking: a file whose
  writer died outside SWMR mode (flags 0x01) is refused by ``h5py.File(path, "r")`` ("already
  open for write"), with ``swmr=True`` ("not already open for SWMR writing"), with
  ``locking=False`` or ``"best-effort"``, with ``HDF5_USE_FILE_LOCKING=FALSE``, and with
  ``libver=("earliest", "v108")``; a copy opened ``"r+"`` is refused too. A writer killed in
  SWMR mode leaves 0x05, which ``swmr=True`` reads as it is (no copy needed then).
- *libver bounds.* ``"earliest"`` gives superblock 0 and ``"v108"`` superblock 2, whose flags
  HDF5 does not check on open; ``"v110"`` up to ``"latest"`` give superblock 3. But SWMR
  writing needs superblock 3 ("superblock version for SWMR is less than 3", src/H5Fsuper.c;
  measured: ``swmr_mode = True`` fails on superblocks 0 and 2), and SWMR is what keeps every
  completed recording readable after a kill (:mod:`aptkt.data.writer`). Clearing the flags is
  what HDF5's ``h5clear`` does, through a private property h5py does not reach: hence the
  rewrite of the superblock, on a private copy, never on the file.
"""

from __future__ import annotations

import ctypes
import functools
import os
import random
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import h5py
import numpy as np

__all__ = [
    "while_locked",
    "open_swmr_read",
    "lookup3",
    "writer_mark",
    "cut_short",
    "copy_without_writer_mark",
    "refused_for_writer_mark",
    "readable_prefix",
]

_LOCK_PATIENCE_S = 10.0

_T = TypeVar("_T")


def while_locked(step: Callable[[], _T]) -> _T:
    """Run an HDF5 open or create (or the switch to SWMR writing), retrying while another process
    holds the file's lock for a moment. A reader opening the file as the writer starts takes the lock
    briefly, and the writer's switch to SWMR mode would otherwise fail with errno 11 and end a
    collection before its first trial (measured: 3 of 60 starts with a reader polling).

    The waits are short and jittered: a reader that polls in a loop holds the lock most of the
    time, and a writer backing off to long, regular waits kept missing the gaps between its
    opens until the patience ran out (seen on a loaded machine)."""
    deadline = time.monotonic() + _LOCK_PATIENCE_S
    delay = 0.002
    while True:
        try:
            return step()
        except (OSError, RuntimeError) as exc:
            if "unable to lock file" not in str(exc) or time.monotonic() > deadline:
                raise
        time.sleep(delay * random.uniform(0.5, 1.5))
        delay = min(2 * delay, 0.005)


# A SWMR reader retries a metadata read whose checksum fails (the writer may be rewriting that
# block at this moment); HDF5's default of 100 attempts backs off exponentially, so on a file
# that is really damaged (truncated) a single read took minutes. A handful of quick attempts
# covers a block caught mid-write.
_SWMR_READ_ATTEMPTS = 12


@functools.cache
def _hdf5_library() -> ctypes.CDLL | None:
    """The HDF5 library h5py runs on (for the one setting h5py does not expose)."""
    for lib in _hdf5_candidates():
        try:
            handle = ctypes.CDLL(str(lib))
            handle.H5Pset_metadata_read_attempts.argtypes = [ctypes.c_int64, ctypes.c_uint]
            return handle
        except (OSError, AttributeError):
            continue
    return None


def _hdf5_candidates() -> list[Path]:
    """Where to look up HDF5's functions: first h5py's own extension module, whose symbol
    lookup (dlsym through its handle) reaches the HDF5 library it was linked with, whatever
    that library's file is called (``h5py.libs/libhdf5-<hash>.so.<version>`` in a Linux wheel);
    then the bundled libraries by name, and the libraries loaded in this process."""
    candidates = [Path(h5py.h5p.__file__)]
    bundled = sorted((Path(h5py.__file__).parent.parent / "h5py.libs").glob("libhdf5-*"))
    if bundled:
        return candidates + bundled
    try:
        with open("/proc/self/maps") as fh:
            loaded = {
                Path(line.split()[-1]) for line in fh if "/libhdf5." in line or "/libhdf5-" in line
            }
    except OSError:
        loaded = set()
    return candidates + sorted(loaded)


def open_swmr_read(path: Path) -> h5py.File:
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


#: lookup3's rotations: of its mix (one block of 12 bytes) and of its final mix.
_MIX = (4, 6, 8, 16, 19, 4)
_FINAL = (14, 11, 25, 16, 4, 14, 24)
_MASK = 0xFFFFFFFF


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _MASK


def lookup3(data: bytes) -> int:
    """Bob Jenkins' lookup3 ``hashlittle`` with seed 0: HDF5's metadata checksum. The state
    (a, b, c) is ``v``; each step of a mix updates one word from the next, in rotation."""
    n = len(data)
    v = [(0xDEADBEEF + n) & _MASK] * 3
    k = 0
    while n > 0:
        block = data[k : k + 12] + bytes(max(0, 12 - n))
        for i in range(3):
            v[i] = (v[i] + int.from_bytes(block[4 * i : 4 * i + 4], "little")) & _MASK
        if n <= 12:  # the last block: the final mix
            for i, r in enumerate(_FINAL):
                x, z = (2, 0, 1)[i % 3], (1, 2, 0)[i % 3]  # c from b, a from c, b from a
                v[x] = ((v[x] ^ v[z]) - _rot(v[z], r)) & _MASK
            return v[2]
        for i, r in enumerate(_MIX):
            x, y, z = i % 3, (i + 1) % 3, (i + 2) % 3  # a -= c ...; c += b; then b, a; c, b
            v[x] = (v[x] - v[z]) & _MASK ^ _rot(v[z], r)
            v[z] = (v[z] + v[y]) & _MASK
        n -= 12
        k += 12
    return v[2]


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


def writer_mark(path: Path) -> int:
    """The superblock's file consistency flags (0: no writer has it open)."""
    try:
        with open(path, "rb") as fh:
            sb = _superblock(fh)
    except OSError:
        return 0
    return 0 if sb is None else sb[1][11]


def cut_short(path: Path) -> bool:
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


def copy_without_writer_mark(path: Path, dest: Path) -> None:
    shutil.copyfile(path, dest)
    with open(dest, "r+b") as fh:
        found = _superblock(fh)
        if found is None:
            return
        offset, sb = found
        sb[11] = 0
        sb[-4:] = lookup3(bytes(sb[:-4])).to_bytes(4, "little")
        fh.seek(offset)
        fh.write(sb)


def refused_for_writer_mark(exc: BaseException) -> bool:
    text = str(exc)
    return "not already open for SWMR writing" in text or "already open for write" in text


def readable_prefix(ds: h5py.Dataset) -> np.ndarray:
    """All of a dataset, or, when its last chunk lies past the end of a file whose writer was
    killed (that chunk belongs to the append in flight), everything before that chunk."""
    try:
        return ds[...]
    except OSError:
        chunk = ds.chunks[0] if ds.chunks else 1
        return ds[: max(0, (ds.shape[0] - 1) // chunk * chunk)]
