"""``StreamParser.feed`` takes single bytes only: bytes, bytearray, and buffers of uint8/int8
(memoryview, numpy, array.array). Anything else — an int64 or float array, a str, an int — is a
TypeError, never its raw memory parsed as a stream."""

from __future__ import annotations

import array

import numpy as np
import pytest
from skin_helpers import random_raw

from aptkt._core import StreamParser
from aptkt.skin.protocol import encode_sensor_packets

STREAM = encode_sensor_packets(random_raw(np.random.default_rng(3), 25))


@pytest.mark.parametrize(
    "wrap",
    [
        bytes,
        bytearray,
        memoryview,
        lambda b: np.frombuffer(b, dtype=np.uint8),
        lambda b: np.frombuffer(b, dtype=np.int8),
        lambda b: memoryview(np.frombuffer(b, dtype=np.uint8)),
        lambda b: array.array("B", b),
        lambda b: array.array("b", b),
        lambda b: memoryview(b).cast("c"),
        lambda b: np.repeat(np.frombuffer(b, dtype=np.uint8), 2)[::2],  # not contiguous
    ],
    ids=[
        "bytes",
        "bytearray",
        "memoryview",
        "u8",
        "i8",
        "mv-u8",
        "array-B",
        "array-b",
        "mv-c",
        "strided",
    ],
)
def test_byte_buffers_parse_alike(wrap):
    expected = StreamParser().feed(STREAM, raw=True)
    assert len(expected["cell_id"]) == 25
    got = StreamParser().feed(wrap(STREAM), raw=True)
    assert got.keys() == expected.keys()
    for k in expected:
        np.testing.assert_array_equal(got[k], expected[k])


@pytest.mark.parametrize(
    "data",
    [
        np.frombuffer(STREAM[:160], dtype=np.int64),
        np.frombuffer(STREAM[:160], dtype=np.float64),
        np.frombuffer(STREAM[:160], dtype=np.uint16),
        np.frombuffer(STREAM[:160], dtype=np.float32),
        array.array("i", [1, 2, 3]),
        memoryview(STREAM[:160]).cast("Q"),
        "text",
        5,
        [1, 2, 3],
        None,
    ],
    ids=["i64", "f64", "u16", "f32", "array-i", "mv-Q", "str", "int", "list", "None"],
)
def test_other_types_are_a_type_error(data):
    parser = StreamParser()
    with pytest.raises(TypeError, match="StreamParser.feed"):
        parser.feed(data)
    # nothing was consumed: the parser still parses a clean stream from its start
    assert len(parser.feed(STREAM, raw=True)["cell_id"]) == 25
