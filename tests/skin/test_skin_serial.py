"""SerialSkin on a virtual serial device: a pty whose master side plays encoded frames, read
through real pyserial at 4,000,000 baud."""

from __future__ import annotations

import time

import numpy as np
import pytest
from skin_helpers import frames, take, wait_until

from aptkt.errors import SilentCellError, SkinDisconnectedError
from aptkt.skin import SerialSkin, StreamParser, encode_packet, encode_sensor_packets
from aptkt.skin.serial_skin import BAUDRATE

CELLS = [1, 2, 3, 4, 5, 6, 7]


def test_streams_every_packet_in_order(adapter):
    raw = frames(np.random.default_rng(0), CELLS, 60)
    with SerialSkin(adapter.port) as skin:
        assert skin.is_open and skin._serial.baudrate == BAUDRATE == 4_000_000
        adapter.stream(raw, rate_hz=250, per_tick=7)  # one 7-cell frame every 4 ms
        got = []
        assert wait_until(lambda: got.append(skin.read()) or sum(map(len, got)) >= 420, timeout=10)
        samples = type(got[0]).concat(got)
        stats = skin.stats
    np.testing.assert_array_equal(samples.cell_id, raw["cell_id"])
    np.testing.assert_array_equal(samples.acc, raw["acc"] / 256)
    np.testing.assert_array_equal(samples.temp[:, 1], raw["temp"][:, 1] * 0.03125)
    np.testing.assert_allclose(
        samples.force, raw["force"] / 1024
    )  # default calibration: 1 N per unit
    assert np.all(np.diff(samples.t_ns) >= 0)  # arrival timestamps, monotonic
    assert stats["packets"] == 420 and stats["bytes_skipped"] == 0 and stats["reads"] >= 1
    assert not skin.is_open


def test_garbage_and_other_packets_on_the_wire(adapter):
    raw = frames(np.random.default_rng(1), CELLS, 10)
    good = encode_sensor_packets(raw)
    noisy = bytearray()
    for i in range(0, len(good), 20):
        noisy += good[i : i + 20]
        if i % 60 == 0:
            noisy += b"\x13\x11\x00\xaa\xff\x03"  # XON/XOFF bytes must pass through untouched
            noisy += encode_packet("ping")
    with SerialSkin(adapter.port) as skin:
        adapter.write(bytes(noisy))
        assert wait_until(lambda: skin.stats["packets"] == 70)
        s = skin.read()
        stats = skin.stats
    np.testing.assert_array_equal(s.cell_id, raw["cell_id"])
    assert stats["other_packets"]["ping"] == 24
    # the stray header 0xFF + 0x03 is rejected when the next header arrives
    assert stats["rejected"]["payload_high_bit"] == 24 and stats["bytes_skipped"] == 24 * 6


def test_recording_and_silent_cell(adapter):
    rng = np.random.default_rng(2)
    raw = frames(rng, CELLS, 100)
    # cell 7 stops after the 20th frame
    keep = ~((raw["cell_id"] == 7) & (np.arange(700) >= 140))
    with SerialSkin(adapter.port) as skin:
        with pytest.raises(SilentCellError, match=r"\[1, 2, 3, 4, 5, 6, 7\]"):
            skin.wait_for_cells(timeout_s=0.05)  # nothing sent yet
        skin.start_recording({"action": "P2"})
        adapter.stream(take(raw, keep), rate_hz=250, per_tick=7)
        skin.wait_for_cells(timeout_s=5)  # all seven cells are talking
        adapter.wait()
        assert wait_until(lambda: skin.stats["packets"] == int(keep.sum()))
        rec = skin.stop_recording()  # cells 1-6 sent until now; cell 7 stopped ~300 ms ago
        time.sleep(0.15)  # longer than the patch's silence timeout: now every cell is silent
        assert skin.silent_cells() == tuple(CELLS)
    assert rec.silent_cells == (7,)
    assert (rec.samples.cell_id == 7).sum() == 20
    assert len(rec.samples) == keep.sum()
    assert rec.metadata["action"] == "P2" and rec.metadata["source"] == "SerialSkin"
    grid = rec.grid("force", 100.0, cells=[1, 2])
    assert grid.shape[0] == 2 and np.isfinite(grid).all()


def test_unplug_mid_stream_raises_and_keeps_the_data(adapter):
    raw = frames(np.random.default_rng(3), CELLS, 30)
    data = encode_sensor_packets(raw)
    skin = SerialSkin(adapter.port)
    skin.open()
    try:
        skin.start_recording()
        adapter.write(data + data[:33])  # the unplug cuts a packet in half
        assert wait_until(lambda: skin.stats["packets"] == 211)
        adapter.unplug()
        assert wait_until(lambda: skin.link_error is not None)
        assert isinstance(skin.link_error, SkinDisconnectedError)
        assert "link lost" in str(skin.link_error) and adapter.port in str(skin.link_error)
        rec = skin.stop_recording()  # what was recorded is kept
        assert len(rec.samples) == 211 and "link_error" in rec.metadata
        assert len(skin.read()) == 211
        with pytest.raises(SkinDisconnectedError):
            skin.read()
        with pytest.raises(SkinDisconnectedError):
            skin.total_normal_force()
        assert skin.stats["link_error"]
    finally:
        skin.close()


def test_missing_port():
    with pytest.raises(SkinDisconnectedError, match="not found"):
        SerialSkin("/dev/aptkt-no-such-port").open()


def test_busy_port(adapter):
    with SerialSkin(adapter.port):
        with pytest.raises(SkinDisconnectedError, match="busy"):
            SerialSkin(adapter.port).open()


def test_parser_reference_for_the_wire_bytes(adapter):
    # The bytes SerialSkin sees are exactly what the encoder produced (raw mode pty).
    raw = frames(np.random.default_rng(4), CELLS, 5)
    data = encode_sensor_packets(raw)
    with SerialSkin(adapter.port) as skin:
        adapter.write(data)
        assert wait_until(lambda: skin.stats["bytes"] == len(data))
    assert skin.stats["bytes_skipped"] == 0
    np.testing.assert_array_equal(StreamParser().feed(data, raw=True)["force"], raw["force"])
