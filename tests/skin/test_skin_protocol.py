"""Encoder, quantiser and parser against the protocol table (Python side)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from skin_helpers import RAW_KEYS, random_raw, reference_decode

from aptkt.skin import (
    PACKET_TYPES,
    RAW_FIELDS,
    RAW_RANGES,
    SCALE,
    StreamParser,
    encode_packet,
    encode_sensor_packets,
    quantize,
)


def test_raw_round_trip_over_the_whole_range():
    rng = np.random.default_rng(1)
    raw = random_raw(rng, 5000)
    for name, ((lo, hi),) in [(k, RAW_RANGES[k]) for k in ("cell_id", "proximity", "acc", "force")]:
        raw[name].flat[:2] = [lo, hi]  # the extremes are representable
    raw["temp"][:2] = [[-128, -8192], [127, 8191]]
    data = encode_sensor_packets(raw)
    assert len(data) == 20 * 5000
    out = StreamParser().feed(data, raw=True)
    for k in RAW_KEYS:
        assert out[k].dtype == RAW_FIELDS[k][1]
        np.testing.assert_array_equal(out[k], raw[k])
    ref = reference_decode(data)
    for k in RAW_KEYS:
        np.testing.assert_array_equal(ref[k], raw[k])


def test_physical_units_follow_the_table():
    rng = np.random.default_rng(2)
    raw = random_raw(rng, 1000)
    out = StreamParser().feed(encode_sensor_packets(raw))
    assert set(out) == set(RAW_KEYS)
    assert (
        out["acc"].shape == (1000, 3)
        and out["temp"].shape == (1000, 2)
        and out["force"].shape == (1000, 3)
    )
    np.testing.assert_array_equal(out["cell_id"], raw["cell_id"])
    np.testing.assert_array_equal(out["proximity"], raw["proximity"] / 65536)
    np.testing.assert_array_equal(out["acc"], raw["acc"] / 256)
    np.testing.assert_array_equal(out["temp"][:, 0], raw["temp"][:, 0] * 0.5 + 24)
    np.testing.assert_array_equal(out["temp"][:, 1], raw["temp"][:, 1] * 0.03125)
    np.testing.assert_array_equal(out["force"], raw["force"] / 1024)
    for k in ("acc", "temp", "force"):
        assert out[k].flags.c_contiguous and out[k].dtype == np.float64


def test_a_packet_written_by_hand():
    # cell 0x1234, proximity 0xBEEF, acc (-1, 5, -512), temp (-3 → 22.5 °C, -2 → -0.0625 °C),
    # force (4095, 1, 2048): bytes worked out from the table by hand.
    packet = bytes(
        [
            0xFF,
            0x24,
            0x34,
            0x5F,
            0x3B,
            0x7F,
            0x00,
            0x40,
            0x7F,
            0x6D,
            0x18,
            0x7F,
            0x1F,
            0x00,
            0x01,
            0x40,
            0x00,
            0x7F,
            0x7E,
            0xAA,
        ]
    )
    out = StreamParser().feed(packet)
    assert out["cell_id"].tolist() == [0x1234]
    assert out["proximity"].tolist() == [0xBEEF / 65536]
    assert out["acc"].tolist() == [[-1 / 256, 5 / 256, -2.0]]
    assert out["temp"].tolist() == [[22.5, -0.0625]]
    assert out["force"].tolist() == [[4095 / 1024, 1 / 1024, 2.0]]
    raw = StreamParser().feed(packet, raw=True)
    assert encode_sensor_packets(raw) == packet


def test_quantize_rounds_half_to_even_clips_and_broadcasts():
    r = quantize(
        [3, 4],
        0.5,
        [[1.0, -3.0, 2.5 / 256], [0, 0, 0]],
        [[24.25, 20.0], [1e9, -1e9]],
        [[0.5, 10.0, -1.0], [0, 0, 0]],
    )
    assert r["proximity"].tolist() == [32768, 32768]
    assert r["acc"].tolist() == [[256, -512, 2], [0, 0, 0]]
    assert r["temp"].tolist() == [[0, 640], [127, -8192]]
    assert r["force"].tolist() == [[512, 4095, 0], [0, 0, 0]]
    assert r["cell_id"].dtype == np.uint16


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.integers(0, 0x3FFF),
            st.floats(-0.5, 1.5),
            st.lists(st.floats(-3, 3), min_size=3, max_size=3),
            st.tuples(st.floats(-60, 110), st.floats(-300, 300)),
            st.lists(st.floats(-1, 5), min_size=3, max_size=3),
        ),
        min_size=1,
        max_size=30,
    )
)
def test_quantize_then_parse_is_the_nearest_representable_value(rows):
    cells, prox, acc, temp, force = (np.array(x, dtype=float) for x in zip(*rows))
    out = StreamParser().feed(
        encode_sensor_packets(quantize(cells.astype(int), prox, acc, temp, force))
    )

    def nearest(x, scale, offset, lo, hi):
        return np.clip(np.round((x - offset) / scale), lo, hi) * scale + offset

    np.testing.assert_array_equal(out["proximity"], nearest(prox, 1 / 65536, 0, 0, 65535))
    np.testing.assert_array_equal(out["acc"], nearest(acc, 1 / 256, 0, -512, 511))
    np.testing.assert_array_equal(out["temp"][:, 0], nearest(temp[:, 0], 0.5, 24, -128, 127))
    np.testing.assert_array_equal(out["temp"][:, 1], nearest(temp[:, 1], 0.03125, 0, -8192, 8191))
    np.testing.assert_array_equal(out["force"], nearest(force, 1 / 1024, 0, 0, 4095))
    # Within range, quantisation error is at most half a step.
    inside = (acc > -2) & (acc < 511 / 256)
    assert np.all(np.abs(out["acc"] - acc)[inside] <= 0.5 / 256)


def test_scale_table_matches_the_parser():
    raw = {
        "cell_id": [1],
        "proximity": [1000],
        "acc": [[-7, 8, 9]],
        "temp": [[-10, 333]],
        "force": [[11, 12, 13]],
    }
    out = StreamParser().feed(encode_sensor_packets({k: np.array(v) for k, v in raw.items()}))
    ((s_p, o_p),) = SCALE["proximity"]
    assert out["proximity"][0] == 1000 * s_p + o_p
    (s0, o0), (s1, o1) = SCALE["temp"]
    assert out["temp"][0].tolist() == [-10 * s0 + o0, 333 * s1 + o1]


@pytest.mark.parametrize(
    ("field", "bad", "message"),
    [
        ("cell_id", [1, 0x4000], "cell_id = 16384"),
        ("acc", [[0, 0, 0], [0, 512, 0]], "acc = 512"),
        ("temp", [[0, 0], [128, 0]], "temp = 128"),
        ("temp", [[0, 0], [0, -8193]], "temp = -8193"),
        ("force", [[0, 0, 0], [4096, 0, 0]], "force = 4096"),
        ("proximity", [0, 70000], "proximity = 70000"),
        ("acc", [[0, 0, 0], [-(2**40), 0, 0]], "acc"),
    ],
)
def test_encoder_names_field_and_row_of_bad_values(field, bad, message):
    raw = random_raw(np.random.default_rng(3), 2)
    raw[field] = np.array(bad, dtype=np.int64)
    with pytest.raises(ValueError, match=rf"row 1: {message}"):
        encode_sensor_packets(raw)


def test_encoder_rejects_bad_shapes_and_types():
    raw = random_raw(np.random.default_rng(4), 3)
    with pytest.raises(KeyError, match="temp"):
        encode_sensor_packets({k: v for k, v in raw.items() if k != "temp"})
    with pytest.raises(ValueError, match=r"acc must have shape \(n, 3\)"):
        encode_sensor_packets({**raw, "acc": raw["acc"][:, :2]})
    with pytest.raises(ValueError, match="force has 2 rows"):
        encode_sensor_packets({**raw, "force": raw["force"][:2]})
    with pytest.raises(TypeError, match="integers"):
        encode_sensor_packets({**raw, "acc": raw["acc"].astype(float)})
    with pytest.raises(ValueError, match="outside"):
        encode_sensor_packets({**raw, "cell_id": np.array([1, 2, 2**64 - 1], dtype=np.uint64)})


def test_quantize_rejects_nan_and_bad_cell_ids():
    with pytest.raises(ValueError, match="row 0: acc is NaN"):
        quantize([1], 0.0, [[np.nan, 0, 0]], [[0, 0]], [[0, 0, 0]])
    with pytest.raises(ValueError, match="cell_id = 16384"):
        quantize([16384], 0.0, [[0, 0, 0]], [[0, 0]], [[0, 0, 0]])
    with pytest.raises(ValueError, match="broadcast"):
        quantize([1, 2], 0.0, [[0, 0]], [[0, 0]], [[0, 0, 0]])
    with pytest.raises(TypeError):
        quantize([1.5], 0.0, [[0, 0, 0]], [[0, 0]], [[0, 0, 0]])


def test_feed_accepts_bytes_like_and_rejects_other_types():
    data = encode_sensor_packets(random_raw(np.random.default_rng(5), 4))
    for form in (bytearray(data), memoryview(data), np.frombuffer(data, dtype=np.uint8)):
        assert StreamParser().feed(form, raw=True)["cell_id"].shape == (4,)
    for bad in ("not bytes", 5, None, [1, 2]):
        with pytest.raises(TypeError, match="bytes-like"):
            StreamParser().feed(bad)
    empty = StreamParser().feed(b"")
    assert empty["acc"].shape == (0, 3) and empty["temp"].shape == (0, 2)


def test_other_packet_types_are_counted_by_name():
    assert (
        PACKET_TYPES["sensor"] == 0xFF and PACKET_TYPES["ping"] == 0xCB and len(PACKET_TYPES) == 16
    )
    sensor = encode_sensor_packets(random_raw(np.random.default_rng(6), 1))
    stream = (
        sensor
        + encode_packet("ping")
        + encode_packet(0xC8, bytes([3] * 18))
        + encode_packet("ping")
        + sensor
    )
    p = StreamParser()
    assert len(p.feed(stream)["cell_id"]) == 2
    st_ = p.stats
    assert st_["packets"] == 2
    assert st_["other_packets"]["ping"] == 2 and st_["other_packets"]["update_rate"] == 1
    assert sum(st_["other_packets"].values()) == 3
    with pytest.raises(ValueError, match="not a known packet header"):
        encode_packet(0x80)
    with pytest.raises(ValueError, match="payload"):
        encode_packet("ping", bytes([0x80] * 18))


def test_stats_and_pending_report_link_health():
    sensor = encode_sensor_packets(random_raw(np.random.default_rng(7), 2))
    p = StreamParser()
    p.feed(b"\x01\x02\x03" + sensor[:30])
    assert p.pending == 10 and p.stats["pending_bytes"] == 10
    p.feed(sensor[30:] + b"\x90")
    s = p.stats
    assert s["packets"] == 2 and s["bytes"] == 44 and s["bytes_skipped"] == 4
    assert s["rejected"] == {"unknown_header": 1, "payload_high_bit": 0, "bad_end_marker": 0}
    assert s["rejected_total"] == 1
    p.feed(sensor[:5])
    p.discard_pending()
    assert p.pending == 0 and p.stats["bytes_skipped"] == 9
    p.reset()
    assert p.stats["bytes"] == 0
    assert "packets=0" in repr(p)


def test_feed_releases_the_gil():
    import sys
    import threading
    import time

    data = encode_sensor_packets(random_raw(np.random.default_rng(8), 1_000_000))  # 20 MB
    counter = [0]
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            counter[0] += 1
            if counter[0] % 100 == 0:
                time.sleep(0)  # hand the GIL back quickly whenever the main thread waits for it

    old = sys.getswitchinterval()
    # No forced switches: the spinner can only run while the main thread has released the GIL.
    sys.setswitchinterval(5.0)
    t = threading.Thread(target=spin)
    try:
        t.start()
        before = counter[0]
        out = StreamParser().feed(data, raw=True)
        ran_during_feed = counter[0] - before
    finally:
        stop.set()
        sys.setswitchinterval(old)
        t.join()
    assert len(out["cell_id"]) == 1_000_000
    assert ran_during_feed > 0
