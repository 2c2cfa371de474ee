"""TsuSkin over loopback UDP against a fake Tactile Section Unit."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest
from skin_helpers import frames, wait_until

from aptkt.errors import SkinDisconnectedError
from aptkt.skin import TsuSkin, encode_packet, encode_sensor_packets

CELLS = [1, 2, 3, 4, 5, 6, 7]


class FakeTsu:
    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.address = self.sock.getsockname()

    def send(self, datagram: bytes, to: tuple[str, int]) -> None:
        self.sock.sendto(datagram, to)

    def send_packets(self, data: bytes, to: tuple[str, int], tsu_port: int = 3) -> None:
        """Each packet as the TSU frames it: port byte + packet without the trailing 0xAA."""
        for i in range(0, len(data), 20):
            assert data[i + 19] == 0xAA
            self.send(bytes([tsu_port]) + data[i : i + 19], to)

    def received(self, timeout: float) -> list[tuple[bytes, float]]:
        out = []
        self.sock.settimeout(0.01)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                d, _ = self.sock.recvfrom(2048)
                out.append((d, time.monotonic()))
            except TimeoutError:
                pass
        return out

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def tsu():
    t = FakeTsu()
    yield t
    t.close()


def test_datagrams_are_reframed_and_parsed(tsu):
    raw = frames(np.random.default_rng(0), CELLS, 20)
    data = encode_sensor_packets(raw)
    with TsuSkin(tsu_address=tsu.address, listen_address=("127.0.0.1", 0)) as skin:
        to = skin.local_address
        tsu.send_packets(data[:700], to, tsu_port=3)
        tsu.send(bytes([3]) + encode_packet("ping")[:19], to)
        tsu.send_packets(data[700:], to, tsu_port=5)
        assert wait_until(lambda: skin.stats["packets"] == 140)
        s = skin.read()
        st = skin.stats
    np.testing.assert_array_equal(s.cell_id, raw["cell_id"])
    np.testing.assert_array_equal(s.acc, raw["acc"] / 256)
    assert st["bytes_skipped"] == 0 and st["other_packets"]["ping"] == 1
    assert st["datagrams"] == 141 and st["datagrams_per_tsu_port"] == {3: 36, 5: 105}


def test_alive_datagram_every_100_ms(tsu):
    with TsuSkin(
        tsu_address=tsu.address, listen_address=("127.0.0.1", 0), alive_payload=b"\x01"
    ) as skin:
        got = tsu.received(0.55)
        sent = skin.stats["alive_sent"]
    assert [d for d, _ in got] == [b"\x01"] * len(got)
    assert 4 <= len(got) <= 7 and sent >= len(got)
    gaps = np.diff([t for _, t in got])
    # Median: robust to one late wake-up of the sender thread on a busy machine.
    assert 0.08 < np.median(gaps) < 0.12 and np.all(gaps < 0.25)


def test_bad_and_foreign_datagrams_are_counted_and_dropped(tsu):
    raw = frames(np.random.default_rng(1), CELLS, 2)
    data = encode_sensor_packets(raw)
    stranger = FakeTsu()
    try:
        with TsuSkin(tsu_address=tsu.address, listen_address=("127.0.0.1", 0)) as skin:
            to = skin.local_address
            tsu.send(bytes([1]) + data[:10], to)  # truncated datagram
            tsu.send(bytes([1]) + data[:20], to)  # a packet *with* its 0xAA: one byte too long
            stranger.send_packets(data, to)  # right framing, wrong sender
            tsu.send_packets(data, to)
            assert wait_until(lambda: skin.stats["packets"] == 14)
            st = skin.stats
    finally:
        stranger.close()
    assert st["bad_datagrams"] == 2 and st["foreign_datagrams"] == 14 and st["datagrams"] == 16
    assert st["bytes_skipped"] == 0


def test_silent_tsu_shows_as_silent_cells(tsu):
    raw = frames(np.random.default_rng(2), CELLS, 3)
    with TsuSkin(tsu_address=tsu.address, listen_address=("127.0.0.1", 0)) as skin:
        skin.start_recording()
        tsu.send_packets(encode_sensor_packets(raw), skin.local_address)
        assert wait_until(lambda: skin.stats["packets"] == 21)
        time.sleep(0.15)
        rec = skin.stop_recording()
        assert skin.silent_cells() == tuple(CELLS)
    assert rec.silent_cells == tuple(CELLS) and len(rec.samples) == 21


def test_port_in_use(tsu):
    with pytest.raises(SkinDisconnectedError, match="cannot listen on udp 127.0.0.1"):
        TsuSkin(tsu_address=tsu.address, listen_address=tsu.address).open()
