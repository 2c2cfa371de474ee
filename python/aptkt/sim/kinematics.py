"""TCP motion as piecewise-constant acceleration: exact positions, velocities and accelerations
at any time, which is what both the contact physics and the accelerometers need."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aptkt._core import Segments

__all__ = ["Trajectory", "trapezoid"]


@dataclass
class Trajectory:
    """Segments ``(t0_ns, p0, v0, a)``; segment i holds from its t0 until the next one starts.

    Before the first segment the TCP rests at the first segment's start; after the last one it
    keeps that segment's motion (the robot appends a resting segment when it stops).
    """

    t0: list[int] = field(default_factory=list)
    p0: list[np.ndarray] = field(default_factory=list)
    v0: list[np.ndarray] = field(default_factory=list)
    a: list[np.ndarray] = field(default_factory=list)

    @classmethod
    def resting(cls, t_ns: int, position: np.ndarray) -> Trajectory:
        traj = cls()
        traj.append(t_ns, position, np.zeros(3), np.zeros(3))
        return traj

    def append(self, t_ns: int, p0: np.ndarray, v0: np.ndarray, a: np.ndarray) -> None:
        """Add a segment starting at ``t_ns`` (drops any segment that starts later: the plan changed)."""
        t_ns = int(t_ns)
        while self.t0 and self.t0[-1] >= t_ns:
            self.t0.pop(), self.p0.pop(), self.v0.pop(), self.a.pop()
        self.t0.append(t_ns)
        self.p0.append(np.asarray(p0, dtype=np.float64).copy())
        self.v0.append(np.asarray(v0, dtype=np.float64).copy())
        self.a.append(np.asarray(a, dtype=np.float64).copy())

    def segment_at(self, t_ns: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """The segment in force at ``t_ns`` (the first one before the trajectory starts)."""
        i = max(int(np.searchsorted(np.asarray(self.t0), t_ns, side="right")) - 1, 0)
        return self.t0[i], self.p0[i], self.v0[i], self.a[i]

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The segments as arrays: start times (S,) and p0, v0, a (S, 3)."""
        return (
            np.asarray(self.t0, dtype=np.int64),
            np.asarray(self.p0, dtype=np.float64),
            np.asarray(self.v0, dtype=np.float64),
            np.asarray(self.a, dtype=np.float64),
        )

    def segments(self, first: int = 0, stop: int | None = None) -> Segments:
        """Segments ``first`` to ``stop`` (exclusive; None: the last) as the compiled core
        takes them."""
        t0, p0, v0, a = self.arrays()
        return Segments(t0[first:stop], p0[first:stop], v0[first:stop], a[first:stop])

    def forget_before(self, t_ns: int) -> None:
        """Drop segments that ended before ``t_ns`` (keeps memory bounded in long sessions)."""
        i = int(np.searchsorted(np.asarray(self.t0), t_ns, side="right")) - 1
        if i > 0:
            del self.t0[:i], self.p0[:i], self.v0[:i], self.a[:i]

    def evaluate(self, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration (each (n, 3)) at times ``t_ns``."""
        t_ns = np.asarray(t_ns, dtype=np.int64)
        if t_ns.size == 0 or len(self.t0) == 1 or int(t_ns.min()) >= self.t0[-1]:
            # Common case (a control tick): every time lies in the newest segment.
            i = len(self.t0) - 1
            tau = np.maximum((t_ns - self.t0[i]) * 1e-9, 0.0)[:, None]
            p0, v0, a = self.p0[i], self.v0[i], self.a[i]
            return (
                p0 + v0 * tau + 0.5 * a * tau**2,
                v0 + a * tau,
                np.broadcast_to(a, (t_ns.size, 3)).copy(),
            )
        starts = np.asarray(self.t0, dtype=np.int64)
        idx = np.clip(np.searchsorted(starts, t_ns, side="right") - 1, 0, len(starts) - 1)
        tau = np.maximum((t_ns - starts[idx]) * 1e-9, 0.0)[:, None]
        p0, v0, a = np.asarray(self.p0)[idx], np.asarray(self.v0)[idx], np.asarray(self.a)[idx]
        return p0 + v0 * tau + 0.5 * a * tau**2, v0 + a * tau, a.copy()

    def state_at(self, t_ns: int) -> tuple[np.ndarray, np.ndarray]:
        p, v, _ = self.evaluate(np.array([t_ns]))
        return p[0], v[0]


def trapezoid(distance: float, v_max: float, a_max: float) -> list[tuple[float, float, float]]:
    """Phases ``(duration s, start speed, acceleration)`` of a rest-to-rest move of ``distance``
    (>= 0) under speed and acceleration limits: accelerate, cruise, decelerate (or a triangle)."""
    if distance <= 0:
        return []
    t_acc = v_max / a_max
    d_acc = 0.5 * a_max * t_acc**2
    if 2 * d_acc >= distance:  # triangle profile
        t_acc = float(np.sqrt(distance / a_max))
        v_peak = a_max * t_acc
        return [(t_acc, 0.0, a_max), (t_acc, v_peak, -a_max)]
    t_cruise = (distance - 2 * d_acc) / v_max
    return [(t_acc, 0.0, a_max), (t_cruise, v_max, 0.0), (t_acc, v_max, -a_max)]
