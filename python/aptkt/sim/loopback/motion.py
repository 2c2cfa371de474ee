"""Motion and force control of the simulated TCP, one control cycle at a time: the Cartesian
motion generators (moveL's online trapezoid, speedL, stops), force mode's admittance loop on
the compliant axes, and the contact wrench the controller measures."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt.sim.loopback.rotvec import interpolate_rotvec, limit_norm, rotvec_to_matrix

__all__ = ["Motion", "ForceMode", "braking_speed", "contact_wrench", "local_stiffness"]

#: A translation's part along the axes the force controller does not own.
Free = Callable[[np.ndarray], np.ndarray]
#: A cycle of a motion: the linear velocity, the orientation to set (or None), whether it ended.
Step = tuple[np.ndarray, np.ndarray | None, bool]


@dataclass
class Motion:
    """A Cartesian motion generator. :meth:`step` gives the linear velocity of each cycle."""

    kind: str  # "movel" | "speedl" | "stop"
    velocity: float = 0.0  # movel: max speed; stop: unused
    acceleration: float = 1.0
    target: np.ndarray | None = None  # movel target pose / speedl target velocity (6)
    start: np.ndarray | None = None
    length: float = 0.0
    progress: float = 0.0
    speed: float = 0.0
    done: bool = False
    asynchronous: bool = False

    @classmethod
    def movel(
        cls,
        pose: np.ndarray,
        target: np.ndarray,
        velocity: np.ndarray,
        v: float,
        a: float,
        asynchronous: bool,
        free: Free,
    ) -> Motion:
        """A straight line from ``pose`` to ``target`` at up to ``v`` (its length along the
        axes ``free`` keeps, or its rotation when it does not translate)."""
        start = pose.copy()
        length = float(np.linalg.norm(free(target[:3] - start[:3])))
        angle = float(np.linalg.norm(target[3:] - start[3:]))
        return cls(
            kind="movel",
            velocity=max(v, 1e-6),
            acceleration=max(a, 1e-6),
            target=target.copy(),
            start=start,
            length=length if length > 1e-9 else angle,
            speed=max(0.0, float(np.linalg.norm(velocity[:3]))) if length > 1e-9 else 0.0,
            asynchronous=asynchronous,
        )

    def step(self, pose: np.ndarray, velocity: np.ndarray, dt: float, free: Free) -> Step:
        """The linear velocity (3) of this cycle, the orientation to set (or None) and whether
        the motion ended in it; sets the angular part of ``velocity`` in place."""
        lin = velocity[:3].copy()
        if self.kind == "speedl":
            assert self.target is not None
            lin = lin + limit_norm(self.target[:3] - lin, self.acceleration * dt)
            velocity[3:] = velocity[3:] + limit_norm(
                self.target[3:] - velocity[3:], self.acceleration * dt
            )
            return lin, None, False
        if self.kind == "stop":
            step = self.acceleration * dt
            lin = limit_norm(lin, max(0.0, float(np.linalg.norm(lin)) - step))
            omega = limit_norm(velocity[3:], max(0.0, float(np.linalg.norm(velocity[3:])) - step))
            velocity[3:] = omega
            return lin, None, not np.any(lin) and not np.any(omega)
        return self._movel_step(pose, velocity, dt, free)

    def _movel_step(self, pose: np.ndarray, velocity: np.ndarray, dt: float, free: Free) -> Step:
        """moveL: an online trapezoid along the straight line to the target."""
        assert self.target is not None and self.start is not None
        velocity[3:] = 0.0
        remaining = self.length - self.progress
        step = self.acceleration * dt
        speed = min(
            self.speed + step, self.velocity, braking_speed(remaining, self.acceleration, dt)
        )
        if remaining <= speed * dt or self.length <= 1e-12:
            self.progress = self.length
            step_speed = remaining / dt if self.length > 1e-12 else 0.0
            self.speed = 0.0
            done = True
        else:
            self.progress += speed * dt
            self.speed = speed
            step_speed = speed
            done = False
        direction = free(self.target[:3] - self.start[:3])
        n = float(np.linalg.norm(direction))
        lin = direction / n * step_speed if n > 1e-12 else np.zeros(3)
        s = 1.0 if self.length <= 1e-12 else self.progress / self.length
        orientation = interpolate_rotvec(self.start[3:], self.target[3:], s)
        if done:
            # Land exactly on the free coordinates of the target (no drift from summing steps).
            lin = free(self.target[:3] - pose[:3]) / dt
        return lin, orientation, done


@dataclass
class ForceMode:
    """URScript ``force_mode``: the task frame, which of its axes are compliant, the wrench to
    apply along them and their speed limits."""

    frame: np.ndarray  # task frame pose (6)
    selection: list[int]
    wrench: np.ndarray
    limits: np.ndarray
    type: int

    def free(self, vec: np.ndarray) -> np.ndarray:
        """Part of a base-frame translation along axes the force controller does not own."""
        r = rotvec_to_matrix(self.frame[3:])
        local = r.T @ vec
        for i in range(3):
            if self.selection[i]:
                local[i] = 0.0
        return r @ local

    def control(
        self,
        lin: np.ndarray,
        applied: np.ndarray,
        current: np.ndarray,
        gain: float,
        stiffness: float,
        acceleration: float,
        dt: float,
    ) -> np.ndarray:
        """``lin`` with its compliant components replaced by the admittance loop's velocity:
        ``applied`` is the force the robot applies to the world, ``current`` the TCP's
        velocity, ``gain`` the admittance (m/s per N), ``stiffness`` the contact's."""
        r = rotvec_to_matrix(self.frame[3:])
        local = r.T @ lin
        applied = r.T @ applied
        current = r.T @ current
        if stiffness > 0:
            # A discrete admittance loop against stiffness k is stable for gain*k*dt < 2;
            # the simulated controller keeps it well damped, as a tuned real one is.
            gain = min(gain, 0.5 / (stiffness * dt))
        for i in range(3):
            if self.selection[i]:
                error = self.wrench[i] - applied[i]
                want = gain * error
                if stiffness > 0:
                    # Never faster than what can still be braked (at the acceleration cap)
                    # before the force error is gone: no overshoot on stiff contacts.
                    reach = braking_speed(abs(error) / stiffness, acceleration, dt)
                    want = max(-reach, min(reach, want))
                want = max(-self.limits[i], min(self.limits[i], want))
                step = acceleration * dt
                local[i] = current[i] + max(-step, min(step, want - current[i]))
        return r @ local


def braking_speed(distance: float, acceleration: float, dt: float) -> float:
    """Fastest speed from which braking by ``acceleration * dt`` per cycle still stops within
    ``distance`` (the discrete form of sqrt(2 a d); the continuous one brakes harder than a)."""
    step = acceleration * dt
    return step * (-0.5 + math.sqrt(0.25 + 2.0 * max(distance, 0.0) / (step * dt)))


def contact_normal(contact: Any) -> np.ndarray:
    return np.asarray(getattr(contact, "normal", (0.0, 0.0, 1.0)), dtype=float)


def local_stiffness(contact: Any, pose: np.ndarray) -> float:
    """The contact's stiffness along its normal at ``pose`` (N/m, a finite difference)."""
    delta = 1e-5
    probe = pose.copy()
    probe[:3] -= contact_normal(contact) * delta
    return max(
        0.0,
        (float(contact.normal_force(probe)) - float(contact.normal_force(pose))) / delta,
    )


def contact_wrench(contact: Any, pose: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """The force (3) the world exerts on the TCP: the contact's normal force and, while
    sliding, its Coulomb friction against the tangential velocity."""
    normal = contact_normal(contact)
    fn = float(contact.normal_force(pose))
    force = fn * normal
    mu = float(getattr(contact, "friction", 0.0) or 0.0)
    if fn > 0 and mu > 0:
        v = velocity[:3]
        tangential = v - normal * float(normal @ v)
        speed = float(np.linalg.norm(tangential))
        if speed > 1e-6:
            force = force - mu * fn * tangential / speed
    return force
