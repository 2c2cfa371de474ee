"""Helpers for the tests that run a loopback controller (the UR10 backend, the loopback itself,
live sessions): loopback addresses, a fake skin with injectable faults, timers.

ur_rtde's RTDE (30004) and script (30003) ports are fixed in the client, so each loopback
needs a loopback address of its own; the first 127.0.0.x with free ports is used (127.0.0.1
unless another test run holds it).
"""

from __future__ import annotations

import dataclasses
import fcntl
import math
import os
import socket
import tempfile
import threading
import time
from collections.abc import Callable

import numpy as np

from aptkt.robot import UR10, Placement
from aptkt.sim.loopback import Loopback
from aptkt.skin import encode_sensor_packets, quantize
from aptkt.skin.config import default_patch
from aptkt.skin.source import SkinSourceBase

SURFACE_Z = 0.0
STIFFNESS = 200.0  # N/m
DOWN = (math.pi, 0.0, 0.0)
START_POSE = (0.0, -0.5, 0.006, *DOWN)
PLACEMENT = Placement("sponge", 0.0, -0.5, SURFACE_Z, (-0.04, -0.54, -0.01), (0.04, -0.46, 0.04))
DEFAULT_CONTACT = {
    "type": "spring",
    "surface_z": SURFACE_Z,
    "stiffness": STIFFNESS,
    "friction": 0.3,
}
FAST = dict(approach_speed=0.01, max_approach_travel=0.03)

_claimed: set[str] = set()
_claim_lock = threading.Lock()
_claim_files: list[int] = []


def _claim_across_processes(host: str) -> bool:
    """Hold a lock on ``host`` for as long as this process lives: two test runs at once (a
    loaded machine's CI, or a load test) would otherwise both find its ports free and both
    start a loopback on it."""
    path = os.path.join(tempfile.gettempdir(), f"aptkt-tests-loopback-{host}.lock")
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return False
    _claim_files.append(fd)  # released by the kernel when this process ends
    return True


def free_loopback_host() -> str:
    """First 127.0.0.x whose UR ports are free (and not handed out in this run, nor to another
    test run on this machine)."""
    with _claim_lock:
        for last in range(1, 60):
            host = f"127.0.0.{last}"
            if host in _claimed or not _claim_across_processes(host):
                continue
            try:
                for port in (30004, 30003, 30002, 30001, 29999):
                    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
                        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                        s.bind((host, port))
            except OSError:
                continue
            _claimed.add(host)
            return host
    raise RuntimeError("no loopback address with free UR ports")


class FakeSkin:
    """A skin reading for tests: the loopback's true contact force, with injectable faults.

    ``scale`` multiplies the force, ``dead`` reports 0 N forever, ``stale_after`` stops the
    updates after that many seconds (``last_update_ns`` freezes, the value too), ``raise_after``
    raises the given exception, ``nan_after`` reports NaN.
    """

    def __init__(self, loopback: Loopback, clock: Callable[[], int] = time.monotonic_ns):
        self.loopback = loopback
        self.clock = clock
        self.scale = 1.0
        self.dead = False
        self.armed_at: float | None = None
        self.stale_after: float | None = None
        self.raise_after: tuple[float, BaseException] | None = None
        self.nan_after: float | None = None
        self._last_value = 0.0
        self._last_ns = clock()
        self.calls = 0
        #: ``(controller time, force)`` of every reading of the loopback's contact.
        self.readings: list[tuple[float, float]] = []

    def arm(self) -> None:
        """Start the fault clocks now."""
        self.armed_at = time.monotonic()

    def _elapsed(self) -> float:
        return -1.0 if self.armed_at is None else time.monotonic() - self.armed_at

    def __call__(self) -> float:
        self.calls += 1
        t = self._elapsed()
        if self.raise_after is not None and t >= self.raise_after[0]:
            raise self.raise_after[1]
        if self.nan_after is not None and t >= self.nan_after:
            return math.nan
        if self.stale_after is not None and t >= self.stale_after:
            return self._last_value
        if self.dead:
            self._last_value = 0.0
        else:
            felt_at, force = self.loopback.contact()
            self.readings.append((felt_at, force))
            self._last_value = self.scale * force
        self._last_ns = self.clock()
        return self._last_value

    def last_update_ns(self) -> int:
        return self._last_ns


def at_rest(loopback: Loopback, settle: float = 0.05) -> dict:
    """The loopback's state once the arm had ``settle`` s to finish stopping."""
    time.sleep(settle)
    return loopback.state()


def in_contact(robot: UR10, skin: FakeSkin) -> float:
    robot.move_above(PLACEMENT, 0.004)
    return robot.approach_contact(skin, 0.05)


def fire_after(seconds: float, action: Callable[[], object]) -> threading.Timer:
    timer = threading.Timer(seconds, action)
    timer.daemon = True
    timer.start()
    return timer


class LoopbackSkin(SkinSourceBase):
    """A skin source for end-to-end tests: 7 cells at 250 Hz, their force sensors sharing the
    loopback's contact force, through the real protocol encoder, parser and calibration."""

    def __init__(
        self, loopback: Loopback, rate_hz: float = 250.0, silence_timeout_s: float | None = None
    ):
        patch = default_patch()
        if silence_timeout_s is not None:  # (a loaded machine stalls this thread for longer)
            patch = dataclasses.replace(patch, silence_timeout_s=silence_timeout_s)
        super().__init__(patch)
        self.loopback = loopback
        self.period = 1.0 / rate_hz
        self.cells = np.array(self.patch.cell_ids, dtype=np.int64)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def open(self) -> None:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        self._mark_opened()
        self.wait_for_cells()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def _run(self) -> None:
        n = len(self.cells)
        while not self._stop.wait(self.period):
            per_sensor = self.loopback.normal_force() / (3 * n)
            force = self.calibration.to_normalised(self.cells, np.full((n, 3), per_sensor))
            raw = quantize(
                self.cells,
                np.zeros(n),
                np.tile([0.0, 0.0, 1.0], (n, 1)),
                np.full((n, 2), 30.0),
                force,
            )
            self._ingest_bytes(encode_sensor_packets(raw), self._now())
