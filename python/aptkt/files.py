"""Files from elsewhere, opened with care: what a path names and what a file declares are
checked before aptkt acts on them or allocates memory for them.

* **Only regular files are ours.** A path aptkt creates, replaces, renames or reads must be a
  regular file (or not exist): a device, a FIFO, a socket or a directory under that name is
  refused by name (:func:`not_a_regular_file`). Renaming ``/dev/null``'s twin away and writing
  a data set in its place, or reading ``/dev/zero`` until memory runs out, are what this
  prevents.
* **Reads are bounded.** :func:`open_regular` opens a file without blocking (opening a FIFO
  waits for a writer), checks that it is a regular file and its size before a byte is read;
  the caller reads it in pieces (lines of bounded length) rather than whole.
* **A file appears whole or not at all.** Every file aptkt writes is written through
  :func:`replaced_atomically` (or :func:`open_atomically`): under a temporary name in the same
  directory, synced, then renamed onto its name and the directory synced. A failure or a kill
  leaves the previous file (or none) and no temporary file behind the failure.
* **Nothing is written through a link.** A symbolic link where aptkt writes a file is replaced
  by the file (the rename replaces the directory entry), never followed: the file it points at,
  wherever it is, stays as it was, and a dangling link creates nothing at its target. A link,
  dangling or not, counts as an earlier file where a command refuses to replace results
  (:func:`present`).
* **NumPy archives** (``.npz``: prior knowledge, saved models) are read member by member
  (:func:`read_npz`): only known members, each header first, the declared sizes of all members
  checked against a limit before any data is decompressed, no pickles.
"""

from __future__ import annotations

import json
import math
import os
import stat
import sys
import uuid
import zipfile
import zlib
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import numpy as np

from aptkt.errors import AptktError, ConfigError, InvalidInputError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = [
    "NPZ_MAX_BYTES",
    "not_a_regular_file",
    "refuse_unless_regular",
    "open_regular",
    "read_npz",
    "json_member",
    "replaced_atomically",
    "open_atomically",
    "write_text_atomically",
    "write_json_atomically",
    "strict_json",
    "present",
    "read_toml",
]

#: Largest total (uncompressed) size of the arrays of a ``.npz`` file aptkt reads (prior
#: knowledge, a saved model). The paper's prior knowledge (15 objects, 7 actions, 20 trials)
#: takes about 2 MB; the limit leaves room for a thousand times that while keeping a hostile or
#: corrupt file from exhausting memory.
NPZ_MAX_BYTES = 2 << 30

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
)


def _kind(mode: int) -> str | None:
    if stat.S_ISREG(mode):
        return None
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def not_a_regular_file(path: str | Path) -> str | None:
    """What ``path`` is when it exists and is not a regular file (``"a FIFO (named pipe)"``,
    ``"a character device"``, ...), following symbolic links; None when it is a regular file
    or does not exist (nor does a link's target)."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    return _kind(mode)


def refuse_unless_regular(
    path: str | Path, error: type[AptktError], where: str | None = None
) -> None:
    """Raise ``error`` naming ``path`` (or ``where``) if it exists and is not a regular file."""
    kind = not_a_regular_file(path)
    if kind is not None:
        raise error(
            f"{where or path}: is {kind}, not a regular file; aptkt reads and writes only "
            "regular files"
        )


#: Longest file name (bytes) whose temporary name keeps its whole name: most file systems allow
#: 255, and the temporary name adds a suffix (and with a unique name a dot and 34 characters).
_NAME_ROOM = 200


@contextmanager
def replaced_atomically(
    path: str | Path, error: type[AptktError], *, temp_suffix: str | None = None
) -> Iterator[Path]:
    """A temporary path beside ``path`` for the caller to write a complete file at (and close
    it); when the block ends without an exception the file is synced, renamed onto ``path``
    (replacing a file there) and the directory synced, so that after a kill or a power cut
    ``path`` holds the old file or the new one, never a part. When the block raises, the
    temporary file is removed and ``path`` is left as it was.

    ``path`` is refused (``error`` naming it) if it exists and is not a regular file: a device
    or a FIFO under that name is never replaced. The temporary name is unique to this write
    (``.<name>.<random>.tmp``, created exclusively), so that writers of the same file at once
    each rename only their own complete file. ``temp_suffix`` names it ``<name><temp_suffix>``
    instead, for side files whose name is documented (a data set's ``.creating``): the caller
    must be the file's only writer (it holds the data set's lock), a leftover of a killed
    write is replaced, and a non-regular file under that name is refused too."""
    path = Path(path)
    refuse_unless_regular(path, error)
    name = path.name
    if len(os.fsencode(name)) > _NAME_ROOM:  # the temporary name must fit the limit too
        name = name[: _NAME_ROOM // 2]
    if temp_suffix is None:
        tmp = path.with_name(f".{name}.{uuid.uuid4().hex}.tmp")
        # Exclusive: never a file someone else made, nor through a link planted there.
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666))
    else:
        tmp = path.with_name(name + temp_suffix)
        refuse_unless_regular(tmp, error)
        tmp.unlink(missing_ok=True)
    try:
        yield tmp
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    _sync_directory(path.parent)


@contextmanager
def open_atomically(
    path: str | Path,
    error: type[AptktError],
    mode: str = "w",
    *,
    encoding: str | None = None,
    newline: str | None = None,
) -> Iterator[IO[Any]]:
    """:func:`replaced_atomically` for a file written through one handle: the open temporary
    file (``mode`` "w" or "wb"; ``encoding`` UTF-8 by default in text mode)."""
    if mode not in ("w", "wb"):
        raise InvalidInputError(f"mode must be 'w' or 'wb', got {mode!r}")
    if mode == "w" and encoding is None:
        encoding = "utf-8"
    with replaced_atomically(path, error) as tmp:
        with open(tmp, mode, encoding=encoding, newline=newline) as fh:
            yield fh


def write_text_atomically(path: str | Path, text: str, error: type[AptktError]) -> Path:
    """``text`` as the UTF-8 file ``path``, by :func:`open_atomically` (a link there is
    replaced, not followed)."""
    with open_atomically(path, error) as fh:
        fh.write(text)
    return Path(path)


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        value = value.item()
    elif isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (set, frozenset)):
        return [_plain(v) for v in sorted(value, key=str)]
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def strict_json(value: Any, *, indent: int | None = 1) -> str:
    """``value`` as JSON every parser reads: NaN and infinities (an interval over one run, an
    accuracy without a test set) as ``null`` — whoever wrote them says why beside them —,
    NumPy numbers and arrays as plain ones, sets as sorted lists, anything else as its text."""
    return json.dumps(_plain(value), indent=indent, allow_nan=False, default=str)


def write_json_atomically(
    path: str | Path, value: Any, error: type[AptktError], *, indent: int | None = 1
) -> Path:
    """:func:`strict_json` of ``value`` written as ``path`` by :func:`write_text_atomically`."""
    return write_text_atomically(path, strict_json(value, indent=indent), error)


def present(path: str | Path) -> bool:
    """Whether anything is at ``path``: a file, a directory, or a link (a dangling one too,
    which :meth:`pathlib.Path.exists` does not see)."""
    return os.path.lexists(path)


def _sync_directory(directory: Path) -> None:
    """The rename made durable (for a power cut; a kill needs nothing more). File systems that
    cannot sync a directory are left as they are."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def open_regular(
    path: str | Path, max_bytes: int, error: type[AptktError], what: str = "the file"
) -> IO[bytes]:
    """``path`` opened for reading in binary, once it is known to be a regular file of at most
    ``max_bytes``: the file is opened without blocking and checked through its descriptor, so
    a FIFO never blocks and a file swapped in after a check is still the one checked. Every
    problem is ``error`` naming the path."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC)
    except OSError as exc:
        raise error(f"{path}: cannot open {what}: {exc.strerror or exc}") from None
    try:
        info = os.fstat(fd)
        kind = _kind(info.st_mode)
        if kind is not None:
            raise error(f"{path}: is {kind}, not a regular file; aptkt reads only regular files")
        if info.st_size > max_bytes:
            raise error(
                f"{path}: {info.st_size} bytes, more than the {max_bytes} bytes {what} may have"
            )
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _header(
    zf: zipfile.ZipFile, member: str, path: Path, error: type[AptktError], kind: str
) -> tuple[tuple[int, ...], np.dtype]:
    with zf.open(member + ".npy") as fh:
        try:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
            elif version == (2, 0):
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
            else:
                raise InvalidInputError(f"format version {version}")
        except (ValueError, OSError, SyntaxError) as exc:
            raise error(f"{path}: member {member!r}: not a NumPy array ({exc})") from None
    if dtype.hasobject or dtype.kind not in "biufU":
        raise error(f"{path}: member {member!r}: arrays of {dtype} are not allowed in a {kind}")
    return tuple(int(n) for n in shape), dtype


def read_npz(
    path: str | Path,
    *,
    known: Callable[[str], bool],
    error: type[AptktError],
    kind: str,
    max_bytes: int = NPZ_MAX_BYTES,
    member_max_bytes: Mapping[str, int] | None = None,
) -> dict[str, np.ndarray]:
    """Every member of the ``.npz`` archive ``path``, by name (``.npy`` left off), read only
    once the whole archive passed its checks: every member ``known``; each header a native
    array type (no objects: nothing is unpickled); the sizes the headers declare within
    ``max_bytes`` together and each within ``member_max_bytes`` (by member); a member
    ``meta`` present. Any problem is ``error`` naming ``path`` and the member; ``kind`` names
    what the file should be (``"prior-knowledge file"``)."""
    path = Path(path)
    # (The archive itself: its members may be stored uncompressed, so it may be as large as
    # what they declare, and some more for the archive's own records.)
    with open_regular(path, 2 * max_bytes, error, f"a {kind}") as raw:
        if not zipfile.is_zipfile(raw):
            raise error(f"{path}: not a {kind} (not an .npz archive)")
        try:
            with zipfile.ZipFile(raw) as zf:
                names = zf.namelist()
                bad = [n for n in names if not n.endswith(".npy") or not known(n[:-4])]
                if bad:
                    raise error(
                        f"{path}: member {bad[0]!r} is not part of a {kind} "
                        f"({len(bad)} unknown member(s)); the file was not read"
                    )
                members = [n[:-4] for n in names]
                if "meta" not in members:
                    raise error(f"{path}: not a {kind} (no member 'meta')")
                headers = {m: _header(zf, m, path, error, kind) for m in members}
                total = 0
                limits = member_max_bytes or {}
                for m, (shape, dtype) in headers.items():
                    size = int(np.prod(shape, dtype=object)) * dtype.itemsize
                    total += size
                    if m in limits and size > limits[m]:
                        raise error(f"{path}: member {m!r} declares {size} bytes")
                    if total > max_bytes:
                        raise error(
                            f"{path}: member {m!r} declares {shape} of {dtype}: the file's "
                            f"arrays exceed the limit of {max_bytes} bytes for a {kind}"
                        )
                arrays = {}
                for m in members:
                    with zf.open(m + ".npy") as fh:
                        arrays[m] = np.lib.format.read_array(fh, allow_pickle=False)
        except (
            zipfile.BadZipFile,
            OSError,
            EOFError,
            ValueError,
            NotImplementedError,  # a compression method zipfile does not know
            RuntimeError,  # an encrypted member
            zlib.error,  # a compressed member's stream damaged before its CRC is checked
        ) as exc:
            if isinstance(exc, error):
                raise
            raise error(f"{path}: damaged {kind} ({exc})") from None
    return arrays


def json_member(
    raw: np.ndarray, path: str | Path, member: str, error: type[AptktError]
) -> dict[str, Any]:
    """The JSON object a member holds as UTF-8 bytes (uint8, 1-D); ``error`` naming the member
    if it holds anything else."""
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise error(f"{path}: member {member!r}: expected JSON bytes (uint8, 1-D)")
    try:
        value = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        what = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
        raise error(f"{path}: member {member!r}: not JSON ({what})") from None
    if not isinstance(value, dict):
        raise error(f"{path}: member {member!r}: expected a JSON object")
    return value


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """A TOML file a user gave (``what``: "a workspace file", "an object library"), each way of
    failing one :class:`ConfigError` naming the path."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: {what.split(' ', 1)[-1]} not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a directory, not {what}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError:  # a binary file given by mistake (a prior's .npz, say)
        raise ConfigError(f"{path}: not {what} (TOML text), not even UTF-8 text") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
