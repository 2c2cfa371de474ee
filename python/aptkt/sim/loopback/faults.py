"""Injected faults beside the protective stop: an external push or a misbehaving controller,
as an extra base-frame velocity of the TCP (:class:`Disturbance`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from aptkt.sim.loopback.rotvec import limit_norm

__all__ = ["Disturbance"]


class Disturbance:
    """An extra TCP velocity, reached at ``acceleration`` (infinite: at once), held until
    ``until`` (controller time), then ramped back to zero at the same rate."""

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        self.target = np.zeros(3)
        self.velocity = np.zeros(3)
        self.acceleration = math.inf
        self.until = 0.0

    def start(
        self, velocity: Sequence[float], duration: float, acceleration: float | None, now: float
    ) -> None:
        self.target = np.asarray(velocity, dtype=float)[:3]
        self.acceleration = math.inf if acceleration is None else float(acceleration)
        self.until = now + float(duration)

    def step(self, now: float, dt: float) -> np.ndarray:
        """The extra velocity of this control cycle."""
        target = self.target if now < self.until else np.zeros(3)
        step = self.acceleration * dt
        delta = target - self.velocity
        self.velocity = self.velocity + (delta if math.isinf(step) else limit_norm(delta, step))
        return self.velocity
