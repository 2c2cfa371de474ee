"""The skin's raw ↔ physical conversion exists once, in the Rust core (``ColumnSpec`` of
``rust/skin/src/sensor.rs``): the parser, :func:`aptkt.skin.protocol.to_physical`,
:func:`aptkt.skin.protocol.quantize`, the store and the simulator's force loop all call it.
These tests check it over every representable raw value of every column, and that Python
keeps no second table or second conversion."""

from __future__ import annotations

import io
import tokenize
from pathlib import Path

import numpy as np
import pytest

from aptkt import _core
from aptkt.errors import InvalidInputError, InvalidTypeError, UnknownNameError
from aptkt.skin import protocol
from aptkt.skin.protocol import (
    RAW_FIELDS,
    RAW_RANGES,
    SCALE,
    StreamParser,
    encode_sensor_packets,
    quantize,
    to_physical,
)

PACKAGE = Path(protocol.__file__).resolve().parents[1]
MEASURED = [name for name, _, _, _ in _core.SENSOR_FIELDS if name != "cell_id"]


def _columns():
    """(field, column, min, max, scale, offset) of every measured column."""
    for name, _, _, columns in _core.SENSOR_FIELDS:
        if name != "cell_id":
            for c, (lo, hi, scale, offset) in enumerate(columns):
                yield name, c, lo, hi, scale, offset


def _rows_varying(name: str, c: int, values: np.ndarray) -> dict[str, np.ndarray]:
    """Raw rows that are all zero (in range) except column ``c`` of ``name``."""
    n = len(values)
    raw = {
        f: np.zeros((n, *tail), dtype=np.int64) + (1 if f == "cell_id" else 0)
        for f, (tail, _) in RAW_FIELDS.items()
    }
    if raw[name].ndim == 1:
        raw[name] = values.astype(np.int64)
    else:
        raw[name][:, c] = values
    return raw


@pytest.mark.parametrize(("name", "c", "lo", "hi", "scale", "offset"), list(_columns()))
def test_python_converts_as_the_parser_over_every_raw_value(name, c, lo, hi, scale, offset):
    values = np.arange(lo, hi + 1)
    raw = _rows_varying(name, c, values)
    parsed = StreamParser().feed(encode_sensor_packets(raw))
    parsed_raw = StreamParser().feed(encode_sensor_packets(raw), raw=True)
    converted = to_physical(name, parsed_raw[name])
    np.testing.assert_array_equal(converted, parsed[name])
    column = converted if converted.ndim == 1 else converted[:, c]
    # The table's arithmetic, written out: the values the wire's documentation defines.
    np.testing.assert_array_equal(column, values * scale + offset)
    # Other integer dtypes convert the same (the store's and the user's arrays).
    np.testing.assert_array_equal(to_physical(name, raw[name]), converted)


@pytest.mark.parametrize(("name", "c", "lo", "hi", "scale", "offset"), list(_columns()))
def test_raw_to_physical_to_raw_is_the_identity(name, c, lo, hi, scale, offset):
    values = np.arange(lo, hi + 1)
    raw = _rows_varying(name, c, values)
    physical = {f: to_physical(f, raw[f]) for f in MEASURED}
    back = quantize(
        raw["cell_id"], physical["proximity"], physical["acc"], physical["temp"], physical["force"]
    )
    for f in RAW_FIELDS:
        np.testing.assert_array_equal(back[f], raw[f], err_msg=f)
        assert back[f].dtype == RAW_FIELDS[f][1]


def test_the_tables_are_the_cores():
    # Built from the core's export, not written down a second time.
    for name, dtype, vector, columns in _core.SENSOR_FIELDS:
        tail = (len(columns),) if vector else ()
        assert RAW_FIELDS[name] == (tail, np.dtype(dtype))
        assert set(RAW_RANGES[name]) == {(lo, hi) for lo, hi, _, _ in columns}
        if name != "cell_id":
            assert set(SCALE[name]) == {(s, o) for _, _, s, o in columns}
    assert list(SCALE) == MEASURED


def test_no_second_conversion_in_python():
    # The scales are read by protocol.py (to build SCALE) and nowhere else in the package:
    # a module that needs physical values calls to_physical / quantize, which call the core.
    readers = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "protocol.py" and path.parent.name == "skin":
            continue
        source = path.read_text(encoding="utf-8")
        for tok in tokenize.generate_tokens(io.StringIO(source).readline):
            if tok.type == tokenize.NAME and tok.string in {"SCALE", "SENSOR_FIELDS"}:
                readers.append(f"{path.relative_to(PACKAGE)}:{tok.start[0]}")
    allowed = {"skin/__init__.py"}  # the re-export for users
    assert {r.split(":")[0] for r in readers} <= allowed, readers


def test_to_physical_refuses_what_is_not_a_raw_field():
    with pytest.raises(UnknownNameError):
        to_physical("cell_id", [1])
    with pytest.raises(InvalidTypeError):
        to_physical("force", np.array([[0.5, 0.0, 1.0]]))
    with pytest.raises(InvalidInputError, match="int16"):
        to_physical("acc", np.array([[70000, 0, 0]]))
    with pytest.raises(InvalidInputError, match="3 columns"):
        to_physical("acc", np.zeros((2, 2), dtype=np.int16))
    with pytest.raises(TypeError):
        _core._to_physical("acc", np.zeros((2, 3), dtype=np.uint16))
    assert to_physical("temp", np.zeros((0, 2), dtype=np.int16)).shape == (0, 2)
