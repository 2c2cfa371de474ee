"""The motions of the Robot protocol on a UR10: each is sent as an asynchronous or speed command
and supervised cycle by cycle (:class:`~aptkt.robot.ur10.supervisor.Supervisor`) instead of a
blocking call, so a skin reading can interrupt it. A fault inside a motion stops the arm,
retracts it upwards while it is still under control, and re-raises.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from aptkt.errors import (
    AptktError,
    InvalidInputError,
    ProgramStoppedError,
    ProtectiveStopError,
    RobotError,
    SafetyLimitError,
)
from aptkt.robot.base import ForceReading, Placement, SafetyLimits
from aptkt.robot.ur10.connection import Connection
from aptkt.robot.ur10.sampling import Sample
from aptkt.robot.ur10.supervisor import Supervisor

__all__ = ["Motions"]


class Motions:
    """move_above / approach_contact / press / slide / lift / wait / stop on a supervised link.

    The tuning parameters are documented on :class:`~aptkt.robot.ur10.UR10`.
    """

    def __init__(
        self,
        link: Connection,
        supervisor: Supervisor,
        limits: SafetyLimits,
        clock: Callable[[], int],
        tool_orientation: tuple[float, ...],
        *,
        transfer_speed: float,
        retract_height: float,
        force_tolerance: float,
        force_tolerance_abs: float,
        settle_samples: int,
        establish_timeout: float,
    ):
        self.link = link
        self.supervisor = supervisor
        self.limits = limits
        self._clock = clock
        self.tool_orientation = tool_orientation
        self.transfer_speed = min(transfer_speed, limits.max_speed)
        self.retract_height = retract_height
        self.force_tolerance = force_tolerance
        self.force_tolerance_abs = force_tolerance_abs
        self.settle_samples = settle_samples
        self.establish_timeout = establish_timeout
        self.contact_z: float | None = None
        #: ``(start_ns, stop_ns)`` of the last hold (press) or constant-speed part of a slide.
        self.action_window_ns: tuple[int, int] | None = None

    def now_ns(self) -> int:
        return int(self._clock())

    def forget(self) -> None:
        """Forget the current object, contact and skin (after a reconnect)."""
        self.supervisor.active = None
        self.supervisor.skin = None
        self.contact_z = None

    # ------------------------------------------------------------------ Robot protocol
    def move_above(self, placement: Placement, clearance: float) -> None:
        sup = self.supervisor
        _positive(clearance, "clearance")
        target = np.array(
            [placement.x, placement.y, placement.surface_z + clearance, *self.tool_orientation]
        )
        if not placement.contains(tuple(target[:3])):
            raise SafetyLimitError(
                f"{clearance * 1000:.1f} mm above {placement.object_name!r} is outside its workspace box"
            )
        sup.check_global(target[:3], f"the point above {placement.object_name!r}")
        with self._motion():
            sup.active = None
            self.contact_z = None
            sup.skin = None
            pose = self.link.peek_pose()
            if pose[2] < target[2] - 1e-4:
                # Leave the current object vertically before travelling sideways.
                up = np.array([*pose[:3], *self.tool_orientation])
                up[2] = target[2]
                self._move_to(up, self.transfer_speed)
            self._move_to(target, self.transfer_speed)
            sup.active = placement

    def approach_contact(self, total_force: ForceReading, threshold: float) -> float:
        sup, link = self.supervisor, self.link
        placement = self._require_active("approach_contact")
        _positive(threshold, "threshold")
        if threshold >= self.limits.max_normal_force:
            raise SafetyLimitError(
                f"contact threshold {threshold} N is not below max_normal_force {self.limits.max_normal_force} N"
            )
        with self._motion():
            sup.skin = total_force
            link.command("zeroFtSensor")  # wrench limits count from the contact-free reading
            sup.reset()
            start = sup.sample()
            if start.skin > threshold:
                self.contact_z = float(start.pose[2])
                return self.contact_z
            # Stop short of the box floor: the stopping distance is v^2 / 2a (25 um by default).
            floor = placement.workspace_min[2] + 0.0005
            bottom = max(start.pose[2] - self.limits.max_approach_travel, floor)
            link.mode = "speed"
            link.command(
                "speedL",
                [0.0, 0.0, -self.limits.approach_speed, 0.0, 0.0, 0.0],
                self.limits.max_acceleration,
                0.0,
            )

            def reached(s: Sample) -> bool:
                if s.skin > threshold:
                    return True
                if s.pose[2] <= bottom:
                    raise SafetyLimitError(
                        f"no contact with {placement.object_name!r} after "
                        f"{(start.pose[2] - s.pose[2]) * 1000:.1f} mm (skin {s.skin:.3f} N <= {threshold} N); "
                        f"stopped at the {'workspace floor' if bottom == floor else 'approach travel limit'}"
                    )
                return False

            travel = start.pose[2] - bottom
            contact = sup.supervise(
                until=reached,
                timeout=travel / self.limits.approach_speed + 2.0,
                what="the approach",
            )
            link.command("speedStop", self.limits.max_acceleration)
            link.mode = None
            self.contact_z = float(contact.pose[2])
            return self.contact_z

    def press(self, depth: float, hold_time: float) -> None:
        self._require_contact("press")
        _positive(depth, "depth")
        _non_negative(hold_time, "hold_time")
        if depth > self.limits.max_depth:
            raise SafetyLimitError(
                f"press depth {depth * 1000:.2f} mm exceeds max_depth {self.limits.max_depth * 1000:.2f} mm"
            )
        if hold_time > self.limits.max_hold_time:
            raise SafetyLimitError(
                f"hold time {hold_time} s exceeds max_hold_time {self.limits.max_hold_time} s"
            )
        assert self.contact_z is not None
        target = np.array([*self.link.peek_pose()[:3], *self.tool_orientation])
        target[2] = self.contact_z - depth
        self.supervisor.check_box(target[:3], "the press depth")
        with self._motion():
            self._move_to(target, self.limits.approach_speed)
            start = self.now_ns()
            self.supervisor.supervise(duration=hold_time, what="the hold")
            self.action_window_ns = (start, self.now_ns())

    def slide(
        self,
        normal_force: float,
        speed: float,
        duration: float,
        direction: tuple[float, float],
        total_force: ForceReading,
    ) -> None:
        sup, link = self.supervisor, self.link
        self._require_contact("slide")
        _positive(normal_force, "normal_force")
        _positive(speed, "speed")
        _positive(duration, "duration")
        if normal_force > self.limits.max_normal_force:
            raise SafetyLimitError(
                f"slide force {normal_force} N exceeds max_normal_force {self.limits.max_normal_force} N"
            )
        if speed > self.limits.max_speed:
            raise SafetyLimitError(
                f"slide speed {speed} m/s exceeds max_speed {self.limits.max_speed} m/s"
            )
        if duration > self.limits.max_hold_time:
            raise SafetyLimitError(
                f"slide time {duration} s exceeds max_hold_time {self.limits.max_hold_time} s"
            )
        dx, dy = float(direction[0]), float(direction[1])
        norm = math.hypot(dx, dy)
        if not norm > 1e-9:
            raise InvalidInputError("slide direction must not be zero")
        dx, dy = dx / norm, dy / norm
        pose = link.peek_pose()
        # Ramp up, `duration` at full speed, ramp down: all of it must stay in the box.
        ramp = speed / self.limits.max_acceleration
        reach = speed * duration + speed * ramp
        sup.check_box(
            np.array([pose[0] + dx * reach, pose[1] + dy * reach, pose[2]]),
            f"a {reach * 1000:.1f} mm slide",
        )
        with self._motion():
            sup.skin = total_force
            sup.reset()
            link.mode = "force"
            # Compliant along base z only, pushing down with the target force (the wrench is
            # what the arm applies to the object); z speed capped at twice the approach speed.
            link.command(
                "forceMode",
                [0.0] * 6,
                [0, 0, 1, 0, 0, 0],
                [0.0, 0.0, -normal_force, 0.0, 0.0, 0.0],
                2,
                [0.005, 0.005, 2.0 * self.limits.approach_speed, 0.1, 0.1, 0.1],
            )
            settled = [0]

            def established(s: Sample) -> bool:
                band = max(self.force_tolerance * normal_force, self.force_tolerance_abs)
                ok = abs(s.skin - normal_force) <= band
                settled[0] = settled[0] + 1 if ok else 0
                return settled[0] >= self.settle_samples

            sup.supervise(
                until=established,
                timeout=self.establish_timeout,
                what=f"establishing {normal_force} N",
            )
            link.mode = "force+speed"
            link.command(
                "speedL",
                [dx * speed, dy * speed, 0.0, 0.0, 0.0, 0.0],
                self.limits.max_acceleration,
                0.0,
            )
            # The controller takes the command at its next cycle and ramps at max_acceleration:
            # full speed one period + `ramp` s after sending (the planned window; the trace in
            # recording_metadata shows the measured speed).
            start = self.now_ns() + int(round((ramp + 1.0 / link.frequency) * 1e9))
            sup.supervise(duration=ramp + duration, what="the slide")
            self.action_window_ns = (start, start + int(round(duration * 1e9)))
            self._leave_force_mode()

    def lift(self, height: float) -> None:
        _positive(height, "height")
        with self._motion():
            self._leave_force_mode()
            self._lift_by(height)
            self.contact_z = None
            self.supervisor.skin = None

    def wait(self, seconds: float) -> None:
        _non_negative(seconds, "seconds")
        with self._motion():
            self.supervisor.supervise(duration=seconds, what="the wait")

    def stop(self) -> None:
        """Stop every motion now. Never raises; sends nothing once the link is lost."""
        link = self.link
        if link.control is None or link.lost is not None:
            return
        decel = self.limits.max_acceleration * 4.0
        # ur_rtde's script kills the speed/force threads in speedStop/forceModeStop, so only
        # stop the modes that are on; stopL ends an asynchronous moveL.
        steps: list[tuple[str, tuple[float, ...]]] = []
        if link.mode in ("speed", "force+speed"):
            steps.append(("speedStop", (decel,)))
        if link.mode in ("force", "force+speed"):
            steps.append(("forceModeStop", ()))
        steps.append(("stopL", (decel,)))
        link.hold = None
        for name, args in steps:
            try:
                if not link.link_ok():
                    break
                link.call(name, *args)
            except AptktError:
                break
        link.mode = None

    # ------------------------------------------------------------------ building blocks
    def _move_to(self, target: np.ndarray, speed: float) -> None:
        """Asynchronous moveL to ``target``, supervised until the controller reports it done."""
        sup, link = self.supervisor, self.link
        speed = min(speed, self.limits.max_speed)
        sup.check_global(target[:3], "the move target")
        start = sup.sample()
        before = link.async_status()
        link.mode = "move"
        link.command("moveL", [float(v) for v in target], speed, self.limits.max_acceleration, True)
        distance = float(np.linalg.norm(target[:3] - start.pose[:3]))
        timeout = 2.0 * (distance / speed + speed / self.limits.max_acceleration) + 1.0

        def finished(s: Sample) -> bool:
            status = link.async_status()
            # Done = the controller ran a new asynchronous operation and it is over.
            return status[0] != before[0] and not status[1]

        done = sup.supervise(until=finished, timeout=timeout, what="the moveL")
        # The receive stream may trail the control stream by a package: read on until it
        # shows a cycle after the one that reported the move done, so the pose is final.
        end = sup.supervise(
            until=lambda s: s.timestamp > done.timestamp, timeout=1.0, what="the moveL"
        )
        link.mode = None
        miss = float(np.linalg.norm(end.pose[:3] - target[:3]))
        if miss > 2e-4:
            raise RobotError(f"the moveL ended {miss * 1000:.2f} mm from its target")

    def _leave_force_mode(self) -> None:
        link = self.link
        mode = link.mode
        if mode in ("speed", "force+speed"):
            link.command("speedStop", self.limits.max_acceleration)
            link.mode = "force" if mode == "force+speed" else None
        if link.mode == "force":
            link.command("forceModeStop")
        link.mode = None

    def _lift_by(self, height: float) -> None:
        sup = self.supervisor
        pose = self.link.peek_pose()
        top = math.inf
        if sup.active is not None:
            top = min(top, sup.active.workspace_max[2])
        if sup.workspace is not None:
            top = min(top, sup.workspace[1][2])
        target = np.array([*pose[:3], *self.tool_orientation])
        target[2] = min(pose[2] + height, top - 1e-6)
        if target[2] > pose[2] + 1e-6:
            self._move_to(target, self.transfer_speed)

    def _require_active(self, what: str) -> Placement:
        self.link.require_link()
        if self.supervisor.active is None:
            raise RobotError(f"{what} needs move_above(placement, ...) first")
        return self.supervisor.active

    def _require_contact(self, what: str) -> None:
        self._require_active(what)
        if self.contact_z is None:
            raise RobotError(f"{what} needs approach_contact(...) first")

    def _motion(self) -> _MotionGuard:
        return _MotionGuard(self)

    def _fail(self, exc: BaseException) -> None:
        """Bring the arm to rest after a fault inside a movement; retract while still in control."""
        link, sup = self.link, self.supervisor
        if link.lost is not None or isinstance(exc, (ProtectiveStopError, ProgramStoppedError)):
            link.mode = None  # the controller already stopped the arm, or we cannot reach it
            return
        self.stop()
        if sup.retracting or link.lost is not None:
            return  # a second fault (or Ctrl-C) while retracting: stopped, no further motion
        if not isinstance(exc, (AptktError, KeyboardInterrupt)):
            return  # a bug: stopped, but do not move on our own
        # Ctrl-C and SIGTERM too: the arm must not be left pressing on the object.
        sup.retracting = True
        try:
            sup.reset()
            self._lift_by(self.retract_height)
            self.contact_z = None
        except AptktError as retract_exc:
            _note(exc, f"retracting after the fault failed too: {retract_exc}")
            self.stop()
        finally:
            sup.retracting = False


class _MotionGuard:
    """Marks a supervised movement; a fault inside it stops the arm, retracts and re-raises."""

    def __init__(self, motions: Motions):
        self.motions = motions

    def __enter__(self) -> None:
        self.motions.link.require_link()
        self.motions.link.in_motion = True

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        try:
            if exc is not None:
                self.motions._fail(exc)
        finally:
            self.motions.link.in_motion = False


def _note(exc: BaseException, text: str) -> None:
    if hasattr(exc, "add_note"):
        exc.add_note(text)


def _positive(value: float, name: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InvalidInputError(f"{name} must be a finite number > 0, got {value!r}")


def _non_negative(value: float, name: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise InvalidInputError(f"{name} must be a finite number >= 0, got {value!r}")
