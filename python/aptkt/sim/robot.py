"""The simulated arm: implements :class:`aptkt.robot.base.Robot` on the simulated world.

It enforces :class:`~aptkt.robot.base.SafetyLimits` where a real arm must: requests beyond a
limit are refused before anything moves; during motion the arm's own wrench sensing (the true
contact force) is checked every control tick, and crossing ``max_normal_force`` stops the arm at
that tick, retracts it and raises :class:`~aptkt.errors.SafetyLimitError`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from aptkt._core import ForceControl, ForcePhase
from aptkt.errors import InvalidInputError, RobotError, SafetyLimitError
from aptkt.robot.base import ForceReading, Placement, SafetyLimits
from aptkt.sim.engine import Driver, StopReason
from aptkt.sim.kinematics import trapezoid

__all__ = ["SimRobot"]

_RETRACT = 0.005  # m, how far the arm backs off after a safety stop


class SimRobot:
    """A Cartesian arm carrying the skin in the simulated world (skin facing down).

    ``control_rate_hz`` is the rate of the PC-side loops that read the skin (guarded approach,
    force control): 125 Hz as a CB3's RTDE. ``depth_error`` (m) is added to every press target
    (the arm's repeatability in this trial).
    """

    def __init__(
        self,
        driver: Driver,
        limits: SafetyLimits | None = None,
        *,
        control_rate_hz: float = 125.0,
        depth_error: float = 0.0,
        force_gain: float = 0.02,
        lean_force_control: bool = True,
        native_force_loop: bool = True,
    ):
        self.driver = driver
        self.limits = limits or SafetyLimits()
        self.tick_ns = int(round(1e9 / control_rate_hz))
        self.depth_error = depth_error
        self.force_gain = force_gain  # m/s per N of force error (admittance of the force loop)
        #: Fast simulation only: the force loop gets the skin's reading computed from the packets
        #: before they are made (same numbers, one light step per tick); see FastDriver.force_loop.
        self.lean_force_control = lean_force_control
        #: With lean force control on a fast driver: run each phase of the loop in the compiled
        #: core (same ticks, same numbers) instead of one Python call per tick.
        self.native_force_loop = native_force_loop
        self._placement: Placement | None = None
        self._contact_z: float | None = None
        #: ``(start_ns, stop_ns)`` of the last hold or constant-speed slide (see aptkt.actions.executor).
        self.action_window_ns: tuple[int, int] | None = None

    # ------------------------------------------------------------------ helpers
    def now_ns(self) -> int:
        return self.driver.now_ns()

    def _pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.driver.engine.tcp()

    def _check_point(self, point: np.ndarray, what: str) -> None:
        if self._placement is not None and not self._placement.contains(
            (float(point[0]), float(point[1]), float(point[2]))
        ):
            raise SafetyLimitError(
                f"{what}: target {np.round(point, 4).tolist()} is outside the workspace of "
                f"{self._placement.object_name!r}"
            )

    def _safety_stop(self, message: str) -> SafetyLimitError:
        """Stop now, retract slowly, and return the error to raise."""
        self.stop()
        p, _ = self._pose()
        try:
            self._linear(
                p + np.array([0.0, 0.0, _RETRACT]), self.limits.approach_speed, check=False
            )
        except RobotError:
            pass  # already stopped; the original error matters
        return SafetyLimitError(message)

    def _linear(self, target: np.ndarray, speed: float, *, check: bool = True) -> None:
        """Rest-to-rest straight move under the speed and acceleration limits."""
        p0, _ = self._pose()
        delta = np.asarray(target, dtype=np.float64) - p0
        dist = float(np.linalg.norm(delta))
        if dist < 1e-9:
            return
        if check:
            self._check_point(target, "move")
        u = delta / dist
        t = self.now_ns()
        p = p0.copy()
        for duration, v0, acc in trapezoid(
            dist, min(speed, self.limits.max_speed), self.limits.max_acceleration
        ):
            self.driver.set_motion(t, p, u * v0, u * acc)
            p = p + u * (v0 * duration + 0.5 * acc * duration**2)
            t += int(round(duration * 1e9))
        self.driver.set_motion(t, target, np.zeros(3), np.zeros(3))
        reached, why = self.driver.run(t, self.tick_ns, wrench_limit=self.limits.max_normal_force)
        if why == StopReason.WRENCH:
            raise self._safety_stop(
                f"contact force above {self.limits.max_normal_force} N during a move"
            )

    # ------------------------------------------------------------------ Robot protocol
    def move_above(self, placement: Placement, clearance: float) -> None:
        if clearance <= 0:
            raise InvalidInputError("clearance must be > 0")
        self._placement = placement
        target = np.array([placement.x, placement.y, placement.surface_z + clearance])
        self._check_point(target, "move_above")
        p, _ = self._pose()
        if p[2] < target[2]:  # rise first so that the move never sweeps through the object
            self._linear(np.array([p[0], p[1], target[2]]), self.limits.max_speed, check=False)
        self._linear(target, self.limits.max_speed)
        self._contact_z = None

    def approach_contact(self, total_force: ForceReading, threshold: float) -> float:
        if threshold <= 0 or threshold >= self.limits.max_normal_force:
            raise SafetyLimitError(
                f"contact threshold {threshold} N must be in (0, {self.limits.max_normal_force})"
            )
        p0, _ = self._pose()
        speed = self.limits.approach_speed
        travel = self.limits.max_approach_travel
        if (
            self._placement is not None
        ):  # the guarded move ends at the workspace floor at the latest
            travel = min(travel, p0[2] - self._placement.workspace_min[2])
        if travel <= 0:
            raise SafetyLimitError("approach: already at the workspace floor")
        t = self.now_ns()
        t_acc = speed / self.limits.max_acceleration
        down = np.array([0.0, 0.0, -1.0])
        self.driver.set_motion(t, p0, np.zeros(3), down * self.limits.max_acceleration)
        p1 = p0 + down * 0.5 * self.limits.max_acceleration * t_acc**2
        t1 = t + int(round(t_acc * 1e9))
        self.driver.set_motion(t1, p1, down * speed, np.zeros(3))
        t_end = t1 + int(round((travel - (p0[2] - p1[2])) / speed * 1e9))
        why = None
        if self.native_force_loop and hasattr(self.driver, "guarded_ticks"):
            # The skin's reading computed from the packets before they are made, the ticks in
            # the compiled core: the same stop as reading the skin every tick (tested).
            with self.driver.force_loop(self.lean_force_control) as reading:
                if reading is not None:
                    why = self.driver.guarded_ticks(
                        t_end, threshold, self.tick_ns, self.limits.max_normal_force
                    )
        if why is None:
            reached, why = self.driver.run(
                t_end,
                self.tick_ns,
                stop=lambda: total_force() > threshold,
                wrench_limit=self.limits.max_normal_force,
            )
        self.stop()
        if why == StopReason.WRENCH:
            raise self._safety_stop(
                f"contact force above {self.limits.max_normal_force} N while approaching"
            )
        if why != StopReason.PREDICATE:
            self._linear(p0, self.limits.max_speed, check=False)
            raise RobotError(
                f"no contact within {travel * 1e3:.1f} mm of approach (threshold {threshold} N)"
            )
        p, _ = self._pose()
        self._contact_z = float(p[2])
        return self._contact_z

    def press(self, depth: float, hold_time: float) -> None:
        if self._contact_z is None:
            raise RobotError("press() needs a contact point: call approach_contact() first")
        if not (0 < depth <= self.limits.max_depth):
            raise SafetyLimitError(
                f"press depth {depth * 1e3:.2f} mm is outside (0, {self.limits.max_depth * 1e3:.2f}] mm"
            )
        if hold_time < 0 or not math.isfinite(hold_time):
            raise InvalidInputError("hold_time must be a finite number >= 0")
        p, _ = self._pose()
        target = np.array([p[0], p[1], self._contact_z - depth - self.depth_error])
        self._check_point(target, "press")
        self._linear(target, self.limits.approach_speed)
        t0 = self.now_ns()
        t1 = t0 + int(round(hold_time * 1e9))
        _, why = self.driver.run(t1, self.tick_ns, wrench_limit=self.limits.max_normal_force)
        if why == StopReason.WRENCH:
            raise self._safety_stop(
                f"contact force above {self.limits.max_normal_force} N during the hold"
            )
        self.action_window_ns = (t0, t1)

    def slide(
        self,
        normal_force: float,
        speed: float,
        duration: float,
        direction: tuple[float, float],
        total_force: ForceReading,
    ) -> None:
        lim = self.limits
        if self._contact_z is None:
            raise RobotError("slide() needs a contact point: call approach_contact() first")
        if not (0 < normal_force < lim.max_normal_force):
            raise SafetyLimitError(
                f"slide force {normal_force} N is outside (0, {lim.max_normal_force}) N"
            )
        if not (0 < speed <= lim.max_speed):
            raise SafetyLimitError(f"slide speed {speed} m/s is outside (0, {lim.max_speed}] m/s")
        if duration <= 0 or not math.isfinite(duration):
            raise InvalidInputError("slide duration must be a finite number > 0")
        d = np.array([direction[0], direction[1], 0.0], dtype=np.float64)
        if not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-9:
            raise InvalidInputError(
                f"slide direction must be a non-zero 2-vector, got {direction!r}"
            )
        d /= np.linalg.norm(d)
        p, _ = self._pose()
        t_acc = speed / lim.max_acceleration
        length = speed * (duration + t_acc)
        self._check_point(p + d * length, "slide")

        phases = [
            (t_acc, lim.max_acceleration),
            (duration, 0.0),
            (t_acc, -lim.max_acceleration),
        ]
        with self.driver.force_loop(self.lean_force_control) as reading:
            if (
                reading is not None
                and self.native_force_loop
                and hasattr(self.driver, "force_ticks")
            ):
                self._native_slide(normal_force, d, phases)
                return
            measure = reading or total_force
            # 1. Establish the normal force (admittance control on the skin's reading).
            settled, t_limit = 0, self.now_ns() + int(3e9)
            while settled < 5:
                err = self._force_tick(normal_force, measure, p_xy_velocity=np.zeros(3))
                settled = settled + 1 if abs(err) < 0.1 * normal_force else 0
                if self.now_ns() > t_limit:
                    self.stop()
                    raise RobotError(
                        f"could not establish {normal_force} N within 3 s (reading off by {err:+.3f} N)"
                    )
            # 2. Accelerate, slide, decelerate, keeping the force.
            v = 0.0
            for k, (span, acc) in enumerate(phases):
                t_start = self.now_ns()
                t_stop = t_start + int(round(span * 1e9))
                while self.now_ns() < t_stop:
                    tau = (self.now_ns() - t_start) * 1e-9
                    self._force_tick(
                        normal_force,
                        measure,
                        p_xy_velocity=d * (v + acc * tau),
                        acc=d * acc,
                        until=min(t_stop, self.now_ns() + self.tick_ns),
                    )
                v = max(v + acc * span, 0.0)
                if k == 1:
                    self.action_window_ns = (t_start, t_stop)
            self.stop()

    def _native_slide(
        self, normal_force: float, d: np.ndarray, phases: list[tuple[float, float]]
    ) -> None:
        """The slide's force loop, phase by phase in the compiled core: the same ticks, limits
        and errors as the Python loop in :meth:`slide` (which the tests compare it with)."""
        lim = self.limits
        assert self._contact_z is not None
        control = ForceControl(
            float(normal_force),
            float(self.force_gain),
            float(lim.approach_speed),
            float(self._contact_z),
            float(lim.max_depth),
            int(self.tick_ns),
            float(lim.max_normal_force),
        )

        def check(status: str, err: float) -> None:
            if status == "timeout":
                self.stop()
                raise RobotError(
                    f"could not establish {normal_force} N within 3 s (reading off by {err:+.3f} N)"
                )
            if status == "too_deep":
                p, _ = self._pose()
                raise self._safety_stop(
                    f"force control pushed {(self._contact_z - p[2]) * 1e3:.2f} mm deep, "
                    f"beyond max_depth {lim.max_depth * 1e3:.2f} mm"
                )
            if status == "wrench":
                raise self._safety_stop(
                    f"contact force above {lim.max_normal_force} N under force control"
                )

        fast: Any = self.driver  # a driver with force_ticks (the caller checked)
        check(*fast.force_ticks(control, ForcePhase.settle(self.now_ns() + int(3e9))))
        v = 0.0
        for k, (span, acc) in enumerate(phases):
            t_start = self.now_ns()
            t_stop = t_start + int(round(span * 1e9))
            ramp = ForcePhase.ramp(t_start, t_stop, v, acc, (float(d[0]), float(d[1])))
            check(*fast.force_ticks(control, ramp))
            v = max(v + acc * span, 0.0)
            if k == 1:
                self.action_window_ns = (t_start, t_stop)
        self.stop()

    def _force_tick(
        self,
        target: float,
        total_force: ForceReading,
        p_xy_velocity: np.ndarray,
        acc: np.ndarray | None = None,
        until: int | None = None,
    ) -> float:
        """One control tick of the force loop; returns the force error before the tick."""
        lim = self.limits
        measured = total_force()
        err = target - measured
        vz = -float(np.clip(self.force_gain * err, -lim.approach_speed, lim.approach_speed))
        p, _ = self._pose()
        if self._contact_z is not None and p[2] < self._contact_z - lim.max_depth:
            raise self._safety_stop(
                f"force control pushed {(self._contact_z - p[2]) * 1e3:.2f} mm deep, "
                f"beyond max_depth {lim.max_depth * 1e3:.2f} mm"
            )
        v = np.array([p_xy_velocity[0], p_xy_velocity[1], vz])
        a = np.zeros(3) if acc is None else np.array([acc[0], acc[1], 0.0])
        now = self.now_ns()
        self.driver.set_motion(now, p, v, a)
        end = now + self.tick_ns if until is None else until
        _, why = self.driver.run(end, self.tick_ns, wrench_limit=lim.max_normal_force)
        if why == StopReason.WRENCH:
            raise self._safety_stop(
                f"contact force above {lim.max_normal_force} N under force control"
            )
        return err

    def lift(self, height: float) -> None:
        if height <= 0:
            raise InvalidInputError("lift height must be > 0")
        p, _ = self._pose()
        self._linear(p + np.array([0.0, 0.0, height]), self.limits.max_speed, check=False)
        self._contact_z = None

    def wait(self, seconds: float) -> None:
        if seconds < 0 or not math.isfinite(seconds):
            raise InvalidInputError("wait time must be a finite number >= 0")
        self.stop()
        t_end = self.now_ns() + int(round(seconds * 1e9))
        _, why = self.driver.run(t_end, self.tick_ns, wrench_limit=self.limits.max_normal_force)
        if why == StopReason.WRENCH:
            raise self._safety_stop(
                f"contact force above {self.limits.max_normal_force} N while waiting"
            )

    def stop(self) -> None:
        engine = self.driver.engine
        with engine.lock:
            p, _ = engine.tcp()
            self.driver.set_motion(self.driver.now_ns(), p, np.zeros(3), np.zeros(3))
