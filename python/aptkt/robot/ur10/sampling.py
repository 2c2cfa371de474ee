"""What the supervision loop samples besides the controller: the skin's total normal force
(checked for freshness), and the trace of robot samples that goes into recording metadata."""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from aptkt.errors import SafetyLimitError, SkinDisconnectedError
from aptkt.robot.base import ForceReading

__all__ = ["Sample", "Trace", "read_skin"]


class Sample:
    """One supervision cycle: host time, controller time, TCP pose/speed/wrench and skin force."""

    __slots__ = ("host_ns", "timestamp", "pose", "speed", "force", "skin")

    def __init__(
        self,
        host_ns: int,
        timestamp: float,
        pose: np.ndarray,
        speed: np.ndarray,
        force: np.ndarray,
        skin: float,
    ):
        self.host_ns = host_ns
        self.timestamp = timestamp
        self.pose = pose
        self.speed = speed
        self.force = force
        self.skin = skin


def read_skin(skin: ForceReading | None, host_ns: int, watchdog_timeout: float) -> float:
    """The skin's total normal force now (0 without a skin); raises when it is stale or NaN."""
    if skin is None:
        return 0.0
    value = float(skin())  # a skin source raises its own SkinError when its link fails
    if not math.isfinite(value):
        raise SafetyLimitError(f"the skin reported a non-finite normal force ({value})")
    last = getattr(skin, "last_update_ns", None)
    if callable(last):
        age = (host_ns - int(last())) * 1e-9
        if age > watchdog_timeout:
            raise SkinDisconnectedError(
                f"no fresh skin data for {age:.2f} s (watchdog {watchdog_timeout} s)"
            )
    return value


class Trace:
    """The last ``seconds`` of supervision samples (sized for a 500 Hz controller)."""

    def __init__(self, seconds: float):
        self._samples: deque[Sample] = deque(maxlen=max(100, int(seconds * 500)))

    def append(self, sample: Sample) -> None:
        self._samples.append(sample)

    def window(
        self, start_ns: int | None = None, stop_ns: int | None = None
    ) -> dict[str, np.ndarray]:
        """Samples in ``[start_ns, stop_ns)`` of the host clock, as arrays by field.

        ``robot_timestamp`` is the controller's own clock (s since boot), so the skin's
        host timestamps and the robot's can be related sample by sample.
        """
        samples = [
            s
            for s in list(self._samples)
            if (start_ns is None or s.host_ns >= start_ns)
            and (stop_ns is None or s.host_ns < stop_ns)
        ]
        return {
            "host_t_ns": np.array([s.host_ns for s in samples], dtype=np.int64),
            "robot_timestamp": np.array([s.timestamp for s in samples], dtype=np.float64),
            "tcp_pose": np.array([s.pose for s in samples], dtype=np.float64).reshape(-1, 6),
            "tcp_speed": np.array([s.speed for s in samples], dtype=np.float64).reshape(-1, 6),
            "tcp_force": np.array([s.force for s in samples], dtype=np.float64).reshape(-1, 6),
            "skin_force": np.array([s.skin for s in samples], dtype=np.float64),
        }

    def metadata(self, start_ns: int, stop_ns: int) -> dict[str, Any]:
        """The trace of ``[start_ns, stop_ns)`` (JSON-able lists) and the median
        host-minus-controller clock offset."""
        tr = self.window(start_ns, stop_ns)
        offset = None
        if len(tr["host_t_ns"]):
            offset = int(
                np.median(tr["host_t_ns"] - np.round(tr["robot_timestamp"] * 1e9).astype(np.int64))
            )
        return {
            "robot_clock_offset_ns": offset,
            "robot_trace": {k: v.tolist() for k, v in tr.items()},
        }
