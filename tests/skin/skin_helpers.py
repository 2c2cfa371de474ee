"""Helpers for the skin tests: random raw packets, an independent decoder written from the
protocol table, and a virtual serial adapter (a pty) that plays encoded frames. Imported by
module name; the pytest fixtures are in conftest.py."""

from __future__ import annotations

import os
import threading
import time
import tty

import numpy as np

from aptkt.skin import encode_sensor_packets

RAW_KEYS = ("cell_id", "proximity", "acc", "temp", "force")


def random_raw(
    rng: np.random.Generator, n: int, cells: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """n random sensor packets covering each field's whole representable range."""
    return {
        "cell_id": (rng.integers(0, 0x4000, n) if cells is None else np.asarray(cells)).astype(
            np.uint16
        ),
        "proximity": rng.integers(0, 0x10000, n).astype(np.uint16),
        "acc": rng.integers(-512, 512, (n, 3)).astype(np.int16),
        "temp": np.stack([rng.integers(-128, 128, n), rng.integers(-8192, 8192, n)], axis=1).astype(
            np.int16
        ),
        "force": rng.integers(0, 4096, (n, 3)).astype(np.uint16),
    }


def reference_decode(stream: bytes) -> dict[str, np.ndarray]:
    """Decode consecutive, known-valid sensor packets with the formulas of the protocol table,
    written independently of the Rust decoder."""
    b = np.frombuffer(stream, dtype=np.uint8).reshape(-1, 20).astype(np.int64)

    def signed(v: np.ndarray, bits: int) -> np.ndarray:
        return np.where(v >= 1 << (bits - 1), v - (1 << bits), v)

    return {
        "cell_id": ((b[:, 1] & 0x7F) << 7) | (b[:, 2] & 0x7F),
        "proximity": ((b[:, 3] & 0x7F) << 9) | ((b[:, 4] & 0x7F) << 2) | ((b[:, 10] >> 3) & 0x3),
        "acc": np.stack(
            [signed(((b[:, 5 + i] & 0x7F) << 3) | (b[:, 8 + i] & 0x7), 10) for i in range(3)],
            axis=1,
        ),
        "temp": np.stack(
            [
                signed(((b[:, 8] << 1) & 0xF0) | ((b[:, 9] >> 3) & 0xF), 8),
                signed(((b[:, 17] & 0x7F) << 7) | (b[:, 18] & 0x7F), 14),
            ],
            axis=1,
        ),
        "force": np.stack(
            [((b[:, 11 + 2 * i] & 0x7F) << 5) | (b[:, 12 + 2 * i] & 0x1F) for i in range(3)], axis=1
        ),
    }


def frames(rng: np.random.Generator, cells: list[int], n_frames: int) -> dict[str, np.ndarray]:
    """n_frames rounds of one packet per cell, cells in order (how a patch streams)."""
    raw = random_raw(rng, n_frames * len(cells), np.tile(cells, n_frames))
    raw["force"] = np.minimum(raw["force"], 1000).astype(np.uint16)
    return raw


def take(raw: dict[str, np.ndarray], index: np.ndarray | slice) -> dict[str, np.ndarray]:
    return {k: v[index] for k, v in raw.items()}


class VirtualAdapter:
    """The master side of a pty: the slave path is what SerialSkin opens, like /dev/ttyUSB0."""

    def __init__(self) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line editing: bytes pass through unchanged
        self.port = os.ttyname(slave)
        self._slave = slave  # kept open so the pty exists until the test ends
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self.master, view)
            view = view[n:]

    def stream(self, raw: dict[str, np.ndarray], rate_hz: float, per_tick: int) -> None:
        """Play packets in the background, ``per_tick`` packets every 1/rate_hz seconds."""
        data = encode_sensor_packets(raw)
        n = len(raw["cell_id"])

        def run() -> None:
            t0 = time.monotonic()
            for k, i in enumerate(range(0, n, per_tick)):
                if self._stop.is_set():
                    return
                delay = t0 + k / rate_hz - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                try:
                    self.write(data[20 * i : 20 * (i + per_tick)])
                except OSError:
                    return

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()

    def wait(self, timeout: float = 10.0) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def unplug(self) -> None:
        """Close the master side: the slave's reader gets EIO, as when a USB adapter vanishes."""
        self._stop.set()
        self.wait()
        if self.master >= 0:
            os.close(self.master)
            self.master = -1

    def close(self) -> None:
        self.unplug()
        if self._slave >= 0:
            os.close(self._slave)
            self._slave = -1


def wait_until(predicate, timeout: float = 5.0, poll: float = 0.005) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll)
    return predicate()
