"""The robot interface every backend implements (simulated world, UR10).

The exploratory-action executor (:mod:`aptkt.actions.executor`) only talks to this protocol, so the
learning code never knows whether the arm is real. Coordinates are metres in the robot base
frame with +z pointing away from the table; the skin faces -z.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from aptkt.errors import InvalidInputError

__all__ = ["Robot", "SafetyLimits", "Placement", "ForceReading", "TimedForceReading"]

#: A function returning the current total normal force on the skin in newtons.
ForceReading = Callable[[], float]


@runtime_checkable
class TimedForceReading(Protocol):
    """A :data:`ForceReading` that also says when its value was last refreshed.

    ``last_update_ns()`` uses the robot's clock (:meth:`Robot.now_ns`). Backends use it for
    their stale-skin watchdog; a plain callable can only be checked for exceptions and NaN.
    """

    def __call__(self) -> float: ...

    def last_update_ns(self) -> int: ...


@dataclass(frozen=True)
class SafetyLimits:
    """Limits enforced in code by every backend; exceeding one aborts and retracts.

    Defaults are conservative for a skin patch on a UR10 exploring household objects.
    """

    max_normal_force: float = 5.0  # N, skin total or TCP wrench along the normal
    max_speed: float = 0.10  # m/s, TCP linear speed
    max_acceleration: float = 0.5  # m/s^2
    max_depth: float = 0.005  # m below the point of light contact
    approach_speed: float = 0.005  # m/s for the guarded move towards contact
    max_approach_travel: float = 0.05  # m the guarded move may travel before giving up
    watchdog_timeout: float = 0.5  # s without fresh skin or robot data
    max_hold_time: float = 60.0  # s an action may hold a contact or slide

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not (value > 0):
                raise InvalidInputError(f"SafetyLimits.{name} must be > 0, got {value!r}")


@dataclass(frozen=True)
class Placement:
    """Where an object lies: the centre of its top surface and the box the TCP may enter."""

    object_name: str
    x: float
    y: float
    surface_z: float
    workspace_min: tuple[float, float, float]
    workspace_max: tuple[float, float, float]
    slide_direction: tuple[float, float] = (1.0, 0.0)

    def contains(self, point: tuple[float, float, float]) -> bool:
        return all(
            lo <= p <= hi for lo, p, hi in zip(self.workspace_min, point, self.workspace_max)
        )


@runtime_checkable
class Robot(Protocol):
    """A Cartesian robot carrying the skin.

    Every motion blocks until done (on simulated time for the simulator). A motion that cannot
    complete safely stops the robot, retracts if it can, and raises a
    :class:`~aptkt.errors.RobotError` subclass.
    """

    limits: SafetyLimits

    def now_ns(self) -> int:
        """The clock that timestamps this robot's motion (and, in simulation, the skin)."""
        ...

    def move_above(self, placement: Placement, clearance: float) -> None:
        """Free-space move to ``clearance`` metres above the placement's surface point."""
        ...

    def approach_contact(self, total_force: ForceReading, threshold: float) -> float:
        """Guarded slow move along -z until ``total_force() > threshold``; returns the contact z."""
        ...

    def press(self, depth: float, hold_time: float) -> None:
        """From the contact point, indent by ``depth`` metres and hold for ``hold_time`` s."""
        ...

    def slide(
        self,
        normal_force: float,
        speed: float,
        duration: float,
        direction: tuple[float, float],
        total_force: ForceReading,
    ) -> None:
        """Establish ``normal_force`` (force control on the normal axis), then move tangentially
        at ``speed`` along ``direction`` for ``duration`` s keeping the force."""
        ...

    def lift(self, height: float) -> None:
        """Retract along +z by ``height`` metres from wherever the TCP is."""
        ...

    def wait(self, seconds: float) -> None:
        """Stay still (out of contact) for ``seconds``: thermal recovery between actions."""
        ...

    def stop(self) -> None:
        """Stop every motion now. Safe to call at any time, also after a fault."""
        ...
