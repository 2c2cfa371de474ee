"""What shapes one simulated UR controller (:class:`ControllerConfig`), the controller
versions it can pose as, and the codes it reports over RTDE and the dashboard: runtime states,
robot modes and safety modes."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from aptkt.errors import InvalidInputError

__all__ = [
    "CB3_VERSION",
    "E_SERIES_VERSION",
    "ControllerConfig",
]

CB3_VERSION = (3, 15, 8, 106339)
E_SERIES_VERSION = (5, 11, 6, 108249)

# Runtime states, robot modes and safety modes as the controller reports them over RTDE.
STOPPING, STOPPED, PLAYING, PAUSING, PAUSED, RESUMING = 0, 1, 2, 3, 4, 5
ROBOT_MODE_POWER_OFF, ROBOT_MODE_IDLE, ROBOT_MODE_RUNNING = 3, 5, 7
SAFETY_NORMAL, SAFETY_PROTECTIVE_STOP = 1, 3


@dataclass
class ControllerConfig:
    """Everything that shapes one simulated controller. JSON-able (it crosses a process pipe)."""

    version: tuple[int, int, int, int] = CB3_VERSION
    start_pose: tuple[float, ...] = (0.0, -0.5, 0.2, math.pi, 0.0, 0.0)
    contact: dict[str, Any] | None = None
    #: Controller-side force limit; above it the controller protective-stops (UR default 150 N).
    protective_force_limit: float = 150.0
    #: Seconds after a protective stop before the dashboard accepts "unlock protective stop"
    #: (5 s on a real controller).
    unlock_delay: float = 5.0
    #: Gaussian noise (N) on the reported TCP force; CB3 estimates it from motor currents.
    force_noise: float = 0.0
    #: Force-mode admittance: TCP speed (m/s) per newton of force error, before gain scaling.
    force_mode_admittance: float = 0.05
    #: Acceleration cap (m/s^2) of the force-controlled axes.
    force_mode_acceleration: float = 0.25
    serial_number: str = "2017300000"
    robot_model: str = "UR10"
    seed: int = 0
    #: The simulated skin patch on the TCP, streamed through a pty (None: no skin). ``{}``
    #: for the defaults, or fields of :class:`aptkt.sim.loopback.tcp_skin.SkinConfig`.
    skin: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        self.version = tuple(int(v) for v in self.version)  # type: ignore[assignment]
        if len(self.version) != 4:
            raise InvalidInputError(f"version must have 4 numbers, got {self.version!r}")
        self.start_pose = tuple(float(v) for v in self.start_pose)
        if len(self.start_pose) != 6:
            raise InvalidInputError("start_pose must be [x, y, z, rx, ry, rz]")

    @property
    def frequency(self) -> float:
        """125 Hz for CB3 (major version 3), 500 Hz for e-Series."""
        return 125.0 if self.version[0] <= 3 else 500.0

    @property
    def polyscope_version(self) -> str:
        return ".".join(str(v) for v in self.version)

    def at_least(self, major: int, minor: int) -> bool:
        """Whether the controller's software is version ``major.minor`` or later."""
        v = self.version
        return v[0] > major or (v[0] == major and v[1] >= minor)
