"""The dashboard server's commands (port 29999), answered as a CB3 dashboard server answers
them: program state, play/pause/stop, power and brakes, protective-stop release, popups and
the log. The socket side is in :mod:`aptkt.sim.loopback.servers`."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

from aptkt.sim.loopback.config import (
    PAUSED,
    PLAYING,
    ROBOT_MODE_IDLE,
    ROBOT_MODE_POWER_OFF,
    ROBOT_MODE_RUNNING,
    SAFETY_NORMAL,
    STOPPED,
    ControllerConfig,
)
from aptkt.sim.loopback.script import ControlScript

__all__ = ["DashboardTarget", "answer"]


class DashboardTarget(Protocol):
    """What the dashboard's commands read and change of a controller
    (:class:`~aptkt.sim.loopback.controller.SimulatedController` is one). Named here, so
    that this module needs nothing of the controller, which calls it."""

    config: ControllerConfig
    program: ControlScript | None
    runtime_state: int
    robot_mode: int
    safety_mode: int
    protective_stop_time: float | None
    protective_stop_reason: str

    @property
    def program_running(self) -> bool: ...

    @property
    def protective_stopped(self) -> bool: ...

    def log(self, message: str) -> None: ...

    def stop_program(self, reason: str) -> None: ...

    def pause(self) -> None: ...


_ROBOT_MODES = {
    ROBOT_MODE_POWER_OFF: "POWER_OFF",
    ROBOT_MODE_IDLE: "IDLE",
    ROBOT_MODE_RUNNING: "RUNNING",
}


def answer(ctl: DashboardTarget, line: str) -> str | None:
    """The reply to one dashboard command (without its newline); None closes the connection.
    The caller holds the controller's lock."""
    cmd = line.strip()
    low = cmd.lower()
    if low == "quit":
        return None
    command = _COMMANDS.get(low)
    if command is not None:
        return command(ctl)
    for prefix, reply in _PREFIXED:
        if low.startswith(prefix):
            return reply(ctl, cmd[len(prefix) :])
    return f"could not understand: '{cmd}'"


def _program_state(ctl: DashboardTarget) -> str:
    name = ctl.program.name if ctl.program else "<unnamed>"
    state = {PLAYING: "PLAYING", PAUSED: "PAUSED"}.get(ctl.runtime_state, "STOPPED")
    return f"{state} {name}"


def _safety(ctl: DashboardTarget, word: str) -> str:
    return f"{word}: {'PROTECTIVE_STOP' if ctl.protective_stopped else 'NORMAL'}"


def _stop(ctl: DashboardTarget) -> str:
    if ctl.runtime_state == STOPPED:
        return "Failed to execute: stop"
    ctl.stop_program("dashboard stop")
    return "Stopped"


def _pause(ctl: DashboardTarget) -> str:
    if ctl.runtime_state != PLAYING:
        return "Failed to execute: pause"
    ctl.pause()
    return "Pausing program"


def _play(ctl: DashboardTarget) -> str:
    if ctl.runtime_state == PAUSED and ctl.program is not None and not ctl.protective_stopped:
        ctl.runtime_state = PLAYING
        return "Starting program"
    return "Failed to execute: play"


def _unlock(ctl: DashboardTarget) -> str:
    if ctl.protective_stopped:
        elapsed = time.monotonic() - (ctl.protective_stop_time or 0.0)
        if elapsed < ctl.config.unlock_delay:
            return (
                "Cannot unlock protective stop until 5s after occurrence. "
                "Always inspect cause of protective stop before unlocking"
            )
        ctl.safety_mode = SAFETY_NORMAL
        ctl.protective_stop_reason = ""
        ctl.log("protective stop released")
    return "Protective stop releasing"


def _power_on(ctl: DashboardTarget) -> str:
    if ctl.robot_mode == ROBOT_MODE_POWER_OFF:
        ctl.robot_mode = ROBOT_MODE_IDLE
    return "Powering on"


def _power_off(ctl: DashboardTarget) -> str:
    ctl.stop_program("power off")
    ctl.robot_mode = ROBOT_MODE_POWER_OFF
    return "Powering off"


def _brake_release(ctl: DashboardTarget) -> str:
    if ctl.robot_mode != ROBOT_MODE_POWER_OFF:
        ctl.robot_mode = ROBOT_MODE_RUNNING
    return "Brake releasing"


def _restart_safety(ctl: DashboardTarget) -> str:
    ctl.safety_mode = SAFETY_NORMAL
    ctl.robot_mode = ROBOT_MODE_POWER_OFF
    return "Restarting safety"


def _add_to_log(ctl: DashboardTarget, message: str) -> str:
    ctl.log(message)
    return "Added log message"


_COMMANDS: dict[str, Callable[[DashboardTarget], str]] = {
    "polyscopeversion": lambda ctl: f"URSoftware {ctl.config.polyscope_version} (loopback)",
    "get serial number": lambda ctl: ctl.config.serial_number,
    "get robot model": lambda ctl: ctl.config.robot_model,
    "is in remote control": lambda ctl: "true",
    "running": lambda ctl: f"Program running: {'true' if ctl.program_running else 'false'}",
    "programstate": _program_state,
    "robotmode": lambda ctl: f"Robotmode: {_ROBOT_MODES.get(ctl.robot_mode, 'RUNNING')}",
    "safetymode": lambda ctl: _safety(ctl, "Safetymode"),
    "safetystatus": lambda ctl: _safety(ctl, "Safetystatus"),
    "stop": _stop,
    "pause": _pause,
    "play": _play,
    "unlock protective stop": _unlock,
    "power on": _power_on,
    "power off": _power_off,
    "brake release": _brake_release,
    "close popup": lambda ctl: "closing popup",
    "close safety popup": lambda ctl: "closing safety popup",
    "restart safety": _restart_safety,
    "get loaded program": lambda ctl: "No program loaded",
    "isprogramsaved": lambda ctl: "true <unnamed>",
    "shutdown": lambda ctl: "Shutting down",
}
#: Commands with an argument: the prefix (lower case, with its space) and the reply to the rest.
_PREFIXED: tuple[tuple[str, Callable[[DashboardTarget, str], str]], ...] = (
    ("popup ", lambda ctl, rest: "showing popup"),
    ("addtolog ", _add_to_log),
    ("load ", lambda ctl, rest: f"File not found: {rest}"),
)
