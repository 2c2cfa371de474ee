"""The safety supervisor: one cycle per RTDE period reads the controller and the skin and checks
every limit, in this order: the link (connected, fresh robot data), protective/emergency stop,
the control program (all three in :meth:`Connection.read`), measured TCP speed and
acceleration, the TCP wrench along the surface normal, the skin's total normal force (and its
freshness), and the workspace box of the current object and of the whole cell. Any violation
raises a typed error; the motions (:mod:`aptkt.robot.ur10.motions`) then stop and retract.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Sequence

import numpy as np

from aptkt.errors import RobotError, SafetyLimitError
from aptkt.robot.base import ForceReading, Placement, SafetyLimits
from aptkt.robot.ur10.connection import Connection
from aptkt.robot.ur10.sampling import Sample, Trace, read_skin

__all__ = ["Supervisor"]

# Controller time over which the measured TCP acceleration is averaged (s).
_ACCEL_WINDOW = 0.03

Box = tuple[tuple[float, ...], tuple[float, ...]]


class Supervisor:
    """Checks every limit once per supervision cycle (see the module docstring).

    ``active`` is the object being explored (its workspace box applies), ``skin`` the force
    reading watched during contact, ``retracting`` relaxes the force and box limits so the
    retreat after a fault is never blocked by them.
    """

    def __init__(
        self,
        link: Connection,
        limits: SafetyLimits,
        clock: Callable[[], int],
        trace: Trace,
        *,
        workspace: Box | None,
        measured_tolerance: float,
        max_supervision_hz: float,
    ):
        self.link = link
        self.limits = limits
        self._clock = clock
        self.trace = trace
        self.workspace = workspace
        self.measured_tolerance = measured_tolerance
        self.max_supervision_hz = max_supervision_hz
        self.active: Placement | None = None
        self.skin: ForceReading | None = None
        self.retracting = False
        self.reset()

    def reset(self) -> None:
        """Forget the history the speed, acceleration and wrench checks look back on."""
        self.link.reset_freshness()
        self._speeds: deque[tuple[float, np.ndarray]] = deque(maxlen=64)
        self._normals: deque[float] = deque(maxlen=3)
        self.last: Sample | None = None

    def sample(self) -> Sample:
        """Read robot and skin once and check every limit. Raises on any violation."""
        host_ns = int(self._clock())
        state = self.link.read()
        ts, pose, speed, force = state.timestamp, state.pose, state.speed, state.force
        skin = (
            0.0 if self.retracting else read_skin(self.skin, host_ns, self.limits.watchdog_timeout)
        )
        sample = Sample(host_ns, ts, pose, speed, force, skin)
        self.last = sample
        self.trace.append(sample)
        lim = self.limits
        v = float(np.linalg.norm(speed[:3]))
        if v > lim.max_speed * self.measured_tolerance:
            raise SafetyLimitError(
                f"measured TCP speed {v:.3f} m/s exceeds the limit {lim.max_speed} m/s"
            )
        if state.fresh:
            self._speeds.append((ts, speed[:3].copy()))
            # Acceleration over at least ACCEL_WINDOW s of controller time: over a single
            # period the last step of any discrete trajectory looks like a spike.
            t0, v0 = self._speeds[0]
            for t_old, v_old in reversed(self._speeds):
                if ts - t_old >= _ACCEL_WINDOW:
                    t0, v0 = t_old, v_old
                    break
            if ts > t0:
                a = float(np.linalg.norm(speed[:3] - v0)) / (ts - t0)
                if a > lim.max_acceleration * self.measured_tolerance:
                    raise SafetyLimitError(
                        f"measured TCP acceleration {a:.2f} m/s^2 exceeds the limit {lim.max_acceleration} m/s^2"
                    )
            self._normals.append(abs(float(force[2])))
        if self.retracting:
            return sample  # moving up and away: force and box limits must not block the retreat
        if len(self._normals) == self._normals.maxlen:
            fn = float(np.median(self._normals))
            if fn > lim.max_normal_force:
                raise SafetyLimitError(
                    f"TCP wrench along the normal {fn:.2f} N exceeds max_normal_force {lim.max_normal_force} N"
                )
        if skin > lim.max_normal_force:
            raise SafetyLimitError(
                f"skin normal force {skin:.3f} N exceeds max_normal_force {lim.max_normal_force} N"
            )
        if self.active is not None and not self.active.contains(tuple(pose[:3])):
            raise SafetyLimitError(
                f"TCP at ({pose[0]:.4f}, {pose[1]:.4f}, {pose[2]:.4f}) left the workspace box of "
                f"{self.active.object_name!r}"
            )
        self.check_global(pose[:3], "the TCP")
        return sample

    def supervise(
        self,
        *,
        until: Callable[[Sample], bool] | None = None,
        duration: float | None = None,
        timeout: float | None = None,
        what: str,
    ) -> Sample:
        """Supervision cycles at the RTDE rate until ``until(sample)`` or ``duration`` s."""
        period = 1.0 / min(self.link.frequency, self.max_supervision_hz)
        start = time.monotonic()
        next_t = start
        while True:
            sample = self.sample()
            elapsed = time.monotonic() - start
            if until is not None and until(sample):
                return sample
            if duration is not None and elapsed >= duration:
                return sample
            if timeout is not None and elapsed >= timeout:
                raise RobotError(f"{what} did not finish within {timeout:.1f} s")
            self.link.kick()
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_t = time.monotonic()

    def check_box(self, point: np.ndarray, what: str) -> None:
        """``point`` must lie in the current object's box and in the cell's."""
        placement = self.active
        if placement is not None and not placement.contains(tuple(point)):
            raise SafetyLimitError(
                f"{what} would leave the workspace box of {placement.object_name!r}"
            )
        self.check_global(point, what)

    def check_global(self, point: Sequence[float] | np.ndarray, what: str) -> None:
        """``point`` must lie in the cell's workspace box (if one is set)."""
        if self.workspace is not None:
            lo, hi = self.workspace
            if not all(a <= p <= b for a, p, b in zip(lo, point, hi)):
                raise SafetyLimitError(f"{what} is outside the robot workspace box")
