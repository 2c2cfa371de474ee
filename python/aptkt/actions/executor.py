"""Run one exploratory action on any robot and skin: the executor shared by every backend.

Sequence (paper §5.2): move above the object, approach until light contact (total normal force
above 0.05 N), record while the movement runs, lift off, wait for the temperature sensors to
recover (30 s). The recording is cropped to the action's window — the hold of a press or static
contact, the constant-speed part of a slide — which the robot reports in its optional
``action_window_ns`` attribute (``(start_ns, stop_ns)`` on the skin's clock); robots without it
get the last ``action.duration`` seconds of the movement.

A robot or skin error once the recording has started is raised as a
:class:`~aptkt.errors.TrialFault` (``from`` the error, which is also its ``cause``) carrying what
was recorded: ``recording`` is the partial recording of a movement that failed (uncropped, with
the skin's calibration, the robot's trace if it keeps one and ``metadata["aborted"]`` naming the
error), or the complete, cropped recording when the fault came afterwards, while lifting or
waiting (``complete`` is then True). An error before the recording (moving above the object,
the approach) is raised as it is: there is nothing to keep.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import asdict, dataclass, replace
from typing import Any

from aptkt import __version__
from aptkt.actions.definition import ExploratoryAction, Movement
from aptkt.errors import AptktError, InvalidInputError, TrialFault, TrialInterrupted
from aptkt.robot.base import Placement, Robot
from aptkt.skin.base import SkinSource
from aptkt.skin.config import ForceCalibration
from aptkt.skin.samples import Recording

__all__ = ["ExplorationSettings", "explore", "crop_recording", "calibration_metadata"]


@dataclass(frozen=True)
class ExplorationSettings:
    """How the executor approaches, lifts and waits (SI units)."""

    clearance: float = 0.003  # m above the placement's surface where the guarded approach starts
    contact_threshold: float = 0.05  # N, light contact (paper §5.2)
    lift_height: float = 0.01  # m after the action
    thermal_wait: float = 30.0  # s for the temperature sensors to recover (paper §5.2)
    stamp_wall_clock: bool = True  # add the UTC time to the metadata (off for reproducible data)

    def __post_init__(self) -> None:
        # Finite too: an infinite wait would fail only after the first action, with the arm
        # having pressed the object and the trial's recording lost.
        for name in ("clearance", "contact_threshold", "lift_height"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise InvalidInputError(f"ExplorationSettings.{name} must be a finite number > 0")
        if not (math.isfinite(self.thermal_wait) and self.thermal_wait >= 0):
            raise InvalidInputError("ExplorationSettings.thermal_wait must be a finite number >= 0")


def crop_recording(rec: Recording, start_ns: int, stop_ns: int) -> Recording:
    """The part of ``rec`` in ``[start_ns, stop_ns)``."""
    start_ns, stop_ns = max(start_ns, rec.start_ns), min(stop_ns, rec.stop_ns)
    return Recording(
        samples=rec.samples.between(start_ns, stop_ns),
        start_ns=start_ns,
        stop_ns=stop_ns,
        cells=rec.cells,
        silent_cells=rec.silent_cells,
        metadata=dict(rec.metadata),
    )


def calibration_metadata(skin: SkinSource) -> dict[str, Any] | None:
    """The skin's force calibration as recordings carry it in their metadata (None without one)."""
    cal = getattr(skin, "calibration", None)
    return cal.to_metadata() if isinstance(cal, ForceCalibration) else None


def explore(
    robot: Robot,
    skin: SkinSource,
    placement: Placement,
    action: ExploratoryAction,
    *,
    trial: int = 0,
    settings: ExplorationSettings | None = None,
    metadata: dict[str, Any] | None = None,
) -> Recording:
    """Apply ``action`` once to the object at ``placement`` and return its :class:`Recording`.

    On a robot or skin error the arm is stopped and lifted if possible; once the recording has
    started the error is raised as a :class:`~aptkt.errors.TrialFault` with the data recorded so
    far.
    """

    settings = settings or ExplorationSettings()
    if hasattr(robot, "action_window_ns"):
        robot.action_window_ns = None
    meta: dict[str, Any] = {
        "object": placement.object_name,
        "action": action.to_dict(),
        "trial": int(trial),
        "placement": asdict(placement),
        "settings": asdict(replace(settings)),
        "robot": type(robot).__name__,
        "skin": type(skin).__name__,
        "software_version": __version__,
    }
    if settings.stamp_wall_clock:
        meta["wall_time_utc"] = _dt.datetime.now(_dt.timezone.utc).isoformat(
            timespec="milliseconds"
        )
    meta.update(metadata or {})

    robot.move_above(placement, settings.clearance)
    contact_z = robot.approach_contact(skin.total_normal_force, settings.contact_threshold)
    meta["contact_z"] = float(contact_z)
    meta["movement_start_ns"] = int(robot.now_ns())
    skin.start_recording(meta)
    try:
        if action.movement is Movement.SLIDE:
            robot.slide(
                action.normal_force,
                action.speed,
                action.slide_time,
                placement.slide_direction,
                skin.total_normal_force,
            )
        else:
            robot.press(action.depth, action.hold_time)
    except AptktError as exc:
        rec = skin.stop_recording()
        # Everything needed to store and understand the partial recording travels with it.
        rec.metadata["calibration"] = calibration_metadata(skin)
        rec.metadata["aborted"] = f"{type(exc).__name__}: {exc}"
        robot_metadata = getattr(robot, "recording_metadata", None)
        if callable(robot_metadata):
            rec.metadata.update(robot_metadata(int(rec.start_ns), int(rec.stop_ns)))
        try:
            robot.stop()
            robot.lift(settings.lift_height)
        except AptktError:
            pass  # the original error is what the caller needs
        raise TrialFault(exc, rec) from exc
    rec = skin.stop_recording()
    window = getattr(robot, "action_window_ns", None)
    if window is None:
        window = (rec.stop_ns - int(round(action.duration * 1e9)), rec.stop_ns)
    rec.metadata["movement_stop_ns"] = int(rec.stop_ns)
    rec.metadata["window_ns"] = [int(window[0]), int(window[1])]
    rec.metadata["calibration"] = calibration_metadata(skin)
    robot_metadata = getattr(robot, "recording_metadata", None)
    if callable(robot_metadata):  # e.g. the UR10's own trace and clock (robot timestamps)
        rec.metadata.update(robot_metadata(int(rec.start_ns), int(rec.stop_ns)))
    out = crop_recording(rec, int(window[0]), int(window[1]))
    try:
        robot.lift(settings.lift_height)
        robot.wait(settings.thermal_wait)
    except AptktError as exc:
        # The action itself completed: its recording is whole and must not be lost.
        raise TrialFault(exc, out, complete=True) from exc
    except KeyboardInterrupt as exc:
        # Ctrl-C while lifting off or in the thermal wait: the same, the skin has stopped
        # recording and only this carries the whole recording out.
        raise TrialInterrupted(exc, out, complete=True) from exc
    return out
