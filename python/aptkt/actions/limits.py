"""Actions against a robot cell's safety limits, checked when the files are read: a limit found
only when the motion starts is found after the arm has travelled to the object (and for a
press, after the approach), so every action is checked against the limits and every object's
box before the first motion. The backends still enforce the same limits while moving."""

from __future__ import annotations

import math
from collections.abc import Iterable

from aptkt.actions.definition import ExploratoryAction, Movement
from aptkt.errors import SafetyLimitError
from aptkt.robot.base import Placement, SafetyLimits

__all__ = ["check_action_limits"]


def _over(action: ExploratoryAction, parameter: str, unit: str, limit: str, bound: float) -> None:
    value = getattr(action, parameter)
    if value > bound:
        raise SafetyLimitError(
            f"action {action.name}: {parameter} = {value:g} {unit} exceeds the limit "
            f"{limit} = {bound:g} {unit}"
        )


def slide_reach(action: ExploratoryAction, limits: SafetyLimits) -> float:
    """How far a slide travels: ramp up, ``slide_time`` at full speed, ramp down (m)."""
    return action.speed * action.slide_time + action.speed * action.speed / limits.max_acceleration


def check_action_limits(
    action: ExploratoryAction, limits: SafetyLimits, placements: Iterable[Placement] = ()
) -> None:
    """Raise :class:`~aptkt.errors.SafetyLimitError` naming the action, the parameter, its value
    and the limit if ``action`` exceeds ``limits``, or (a slide) would leave an object's box."""
    if action.movement is Movement.SLIDE:
        _over(action, "normal_force", "N", "max_normal_force", limits.max_normal_force)
        _over(action, "speed", "m/s", "max_speed", limits.max_speed)
        _over(action, "slide_time", "s", "max_hold_time", limits.max_hold_time)
        reach = slide_reach(action, limits)
        for p in placements:
            n = math.hypot(*p.slide_direction)
            dx, dy = p.slide_direction[0] / n, p.slide_direction[1] / n
            end = (p.x + dx * reach, p.y + dy * reach, p.surface_z)
            if not p.contains(end):
                raise SafetyLimitError(
                    f"action {action.name}: a slide of {reach * 1000:.1f} mm (speed "
                    f"{action.speed:g} m/s for {action.slide_time:g} s) would leave the box of "
                    f"object {p.object_name} (workspace_min {list(p.workspace_min)}, "
                    f"workspace_max {list(p.workspace_max)})"
                )
    else:
        _over(action, "depth", "m", "max_depth", limits.max_depth)
        _over(action, "hold_time", "s", "max_hold_time", limits.max_hold_time)
