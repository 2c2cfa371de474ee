"""The skin's wire protocol: streaming parser, quantiser and encoder (all implemented in Rust).

See ``docs/protocol.md`` (the hardware contract). Every packet is 20 bytes; sensor packets
(header 0xFF) carry one cell's proximity, 3-axis acceleration, 2 temperatures and 3 forces.

* :class:`StreamParser` turns a byte stream, fed in arbitrary chunks, into numpy columns.
* :func:`quantize` maps physical values onto the raw integers the wire can carry.
* :func:`encode_sensor_packets` turns raw integers into wire bytes (used by the simulator and
  by the tests; ``StreamParser().feed(encode_sensor_packets(r), raw=True)`` returns ``r``).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from aptkt._core import PACKET_LEN, PACKET_TYPES, SENSOR_FIELDS, StreamParser
from aptkt._core import _encode_sensor_packets as _encode_core
from aptkt._core import _quantize as _quantize_core
from aptkt._core import _to_physical as _to_physical_core
from aptkt._core import encode_packet_bytes as _encode_packet_core
from aptkt.errors import InvalidInputError, InvalidTypeError, UnknownNameError

__all__ = [
    "StreamParser",
    "PACKET_LEN",
    "PACKET_TYPES",
    "PACKET_RATE_HZ",
    "RAW_FIELDS",
    "RAW_RANGES",
    "SCALE",
    "to_physical",
    "quantize",
    "encode_sensor_packets",
    "encode_packet",
]


#: Sensor packets per cell and second: the rate the patches are set to (command 0xC8, argument
#: 0x03; the skin also offers 63 and 125 Hz). The simulated skins send at it, and feature
#: extraction resamples recordings onto it.
PACKET_RATE_HZ = 250.0


def _distinct(columns: list[tuple[int, int, float, float]], pick: slice) -> tuple[Any, ...]:
    """Per-column values; one entry when every column shares them (acc, force)."""
    rows: tuple[tuple[Any, ...], ...] = tuple(tuple(c)[pick] for c in columns)
    return rows[:1] if len(set(rows)) == 1 else rows


# Everything below is read from the Rust crate's table (``aptkt._core.SENSOR_FIELDS``): the
# wire's fields, ranges and scales exist once, in rust/skin.

#: Raw sensor fields: trailing shape and the dtype ``feed(raw=True)`` / :func:`quantize` return.
RAW_FIELDS: Mapping[str, tuple[tuple[int, ...], np.dtype]] = MappingProxyType(
    {
        name: (((len(columns),) if vector else ()), np.dtype(dtype))
        for name, dtype, vector, columns in SENSOR_FIELDS
    }
)

#: Representable raw values per field (per column for ``temp``), inclusive.
RAW_RANGES: Mapping[str, tuple[tuple[int, int], ...]] = MappingProxyType(
    {name: _distinct(columns, slice(0, 2)) for name, _, _, columns in SENSOR_FIELDS}
)

#: physical = raw * scale + offset, per field (temp: per column): proximity 0..1, acc in g,
#: temp in °C (accelerometer die, LM71), force normalised (calibration to newtons is per cell).
SCALE: Mapping[str, tuple[tuple[float, float], ...]] = MappingProxyType(
    {
        name: _distinct(columns, slice(2, 4))
        for name, _, _, columns in SENSOR_FIELDS
        if name != "cell_id"  # an identity, not a measurement
    }
)


def to_physical(name: str, raw: ArrayLike) -> np.ndarray:
    """Raw integers of field ``name`` → physical units (float64, same shape), with the Rust
    core's conversion: the one :meth:`StreamParser.feed` applies, bit for bit.

    ``raw`` holds integers of any dtype whose values fit the field's 16-bit type (uint16, or
    int16 for ``acc`` and ``temp``); a vector field's columns are its last axis.
    """
    if name not in SCALE:
        raise UnknownNameError(
            f"to_physical: {name!r} is not a measured field ({', '.join(SCALE)})"
        )
    _, dtype = RAW_FIELDS[name]
    arr = np.asarray(raw)
    if arr.dtype != dtype:
        if arr.dtype.kind not in "iu":
            raise InvalidTypeError(f"{name}: raw values must be integers, got dtype {arr.dtype}")
        info = np.iinfo(dtype)
        if arr.size and (arr.min() < info.min or arr.max() > info.max):
            raise InvalidInputError(
                f"{name}: raw values must fit {dtype} ({info.min}..{info.max}), got "
                f"{arr.min()}..{arr.max()}"
            )
        arr = arr.astype(dtype)
    return _to_physical_core(name, np.ascontiguousarray(arr))


def _float_rows(name: str, value: ArrayLike, n: int, width: int | None) -> np.ndarray:
    shape = (n,) if width is None else (n, width)
    arr = np.asarray(value, dtype=np.float64)
    try:
        arr = np.broadcast_to(arr, shape)
    except ValueError:
        raise InvalidInputError(
            f"{name}: shape {arr.shape} does not broadcast to {shape}"
        ) from None
    return np.ascontiguousarray(arr)


def _int64(name: str, value: ArrayLike) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "iu":
        raise InvalidTypeError(f"{name} must hold integers, got dtype {arr.dtype}")
    if arr.dtype == np.uint64 and arr.size and int(arr.max()) > np.iinfo(np.int64).max:
        raise InvalidInputError(f"{name}: value {int(arr.max())} is outside every field's range")
    return np.ascontiguousarray(arr, dtype=np.int64)


def quantize(
    cell_id: ArrayLike,
    proximity: ArrayLike,
    acc_g: ArrayLike,
    temp_c: ArrayLike,
    force_norm: ArrayLike,
) -> dict[str, np.ndarray]:
    """Physical values → the raw integers the wire carries.

    Each value is divided by its scale (after removing the offset), rounded half to even and
    clipped to the field's representable range (``RAW_RANGES``). ``cell_id`` is ``(n,)``
    integers in 0..16383 (an identity: out of range raises ``ValueError``); the other inputs
    broadcast to ``proximity`` (n,), ``acc_g`` (n, 3) in g, ``temp_c`` (n, 2) in °C
    (accelerometer die, LM71) and ``force_norm`` (n, 3) normalised. NaN raises ``ValueError``.
    Returns the dict :meth:`StreamParser.feed` returns with ``raw=True``.
    """
    cells = _int64("cell_id", np.atleast_1d(cell_id))
    if cells.ndim != 1:
        raise InvalidInputError(f"cell_id must be 1-D, got shape {cells.shape}")
    n = cells.shape[0]
    return _quantize_core(
        cells,
        _float_rows("proximity", proximity, n, None),
        _float_rows("acc_g", acc_g, n, 3),
        _float_rows("temp_c", temp_c, n, 2),
        _float_rows("force_norm", force_norm, n, 3),
    )


def encode_sensor_packets(raw: Mapping[str, np.ndarray]) -> bytes:
    """Raw integer fields → consecutive 20-byte sensor packets, one per row.

    ``raw`` has the keys of :data:`RAW_FIELDS`: ``cell_id`` (n,), ``proximity`` (n,), ``acc``
    (n, 3), ``temp`` (n, 2), ``force`` (n, 3), any integer dtype. A value outside its field's
    bit width raises ``ValueError`` naming the field and the row (nothing is wrapped silently).
    """
    missing = [k for k in RAW_FIELDS if k not in raw]
    if missing:
        raise UnknownNameError(f"encode_sensor_packets: missing field(s) {', '.join(missing)}")
    cols = {}
    n = None
    for name, (tail, _) in RAW_FIELDS.items():
        arr = _int64(name, raw[name])
        if arr.ndim != 1 + len(tail) or arr.shape[1:] != tail:
            expected = "(" + ", ".join(["n", *map(str, tail)]) + (",)" if not tail else ")")
            raise InvalidInputError(f"{name} must have shape {expected}, got {arr.shape}")
        if n is None:
            n = arr.shape[0]
        elif arr.shape[0] != n:
            raise InvalidInputError(f"{name} has {arr.shape[0]} rows, cell_id has {n}")
        cols[name] = arr
    return _encode_core(
        cols["cell_id"], cols["proximity"], cols["acc"], cols["temp"], cols["force"]
    )


def encode_packet(kind: str | int, payload: bytes = bytes(18)) -> bytes:
    """One packet of any type (by name from :data:`PACKET_TYPES` or header byte) from its 18
    payload bytes, each < 0x80. Useful to emit commands or to test handling of other types."""
    header = PACKET_TYPES[kind] if isinstance(kind, str) else int(kind)
    return _encode_packet_core(header, bytes(payload))
