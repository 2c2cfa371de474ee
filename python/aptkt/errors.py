"""Typed errors of aptkt. Everything raised on purpose derives from :class:`AptktError`."""

from __future__ import annotations

from aptkt._core import AptktError, KernelNotPositiveDefiniteError

__all__ = [
    "AptktError",
    "SkinError",
    "SkinDisconnectedError",
    "SilentCellError",
    "RobotError",
    "SafetyLimitError",
    "ProtectiveStopError",
    "RobotConnectionError",
    "ProgramStoppedError",
    "ConfigError",
    "PriorFileError",
    "NotFittedError",
    "KernelNotPositiveDefiniteError",
]


class ConfigError(AptktError, ValueError):
    """A configuration file or value is invalid; the message names the file and the field."""


class PriorFileError(AptktError, ValueError):
    """A prior-knowledge file is not one, is damaged, or is inconsistent; the message names the
    file and the member."""


class NotFittedError(AptktError, AttributeError):
    """A model was used before ``fit``."""


class SkinError(AptktError):
    """The skin link failed."""


class SkinDisconnectedError(SkinError):
    """The port is missing, busy, or was unplugged mid-stream. Data recorded so far is kept."""


class SilentCellError(SkinError):
    """A cell of the patch stopped sending during a recording."""


class RobotError(AptktError):
    """The robot could not complete a motion. It has been stopped; recorded data is kept."""


class SafetyLimitError(RobotError):
    """A force, speed, acceleration or workspace limit would have been or was exceeded."""


class ProtectiveStopError(RobotError):
    """The controller entered a protective or emergency stop."""


class RobotConnectionError(RobotError):
    """The connection to the controller was lost or could not be established."""


class ProgramStoppedError(RobotError):
    """The control program on the controller stopped or paused (pendant or dashboard stop, the
    controller's communication watchdog, a script error); the arm no longer follows commands."""
