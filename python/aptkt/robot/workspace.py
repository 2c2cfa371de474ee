"""Where the objects lie: the workspace configuration file of a robot cell (TOML).

Example (metres, robot base frame, +z up, the skin faces -z)::

    [robot]
    host = "192.168.1.10"              # optional; the command line may override it
    tool_orientation = [3.14159265, 0.0, 0.0]   # TCP rotation vector while exploring
    workspace_min = [-0.80, -0.90, -0.02]       # optional box every motion stays in
    workspace_max = [ 0.80, -0.20,  0.60]

    [robot.limits]                     # optional: any SafetyLimits field
    max_normal_force = 5.0

    [[object]]
    name = "sponge"
    x = 0.10
    y = -0.55
    surface_z = 0.031                  # top surface at the point the skin touches
    workspace_min = [0.05, -0.60, 0.00]
    workspace_max = [0.15, -0.50, 0.20]
    slide_direction = [1.0, 0.0]       # optional, default +x

Every problem raises :class:`~aptkt.errors.ConfigError` naming the file and the field.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from aptkt.errors import ConfigError
from aptkt.files import read_toml
from aptkt.robot.base import Placement, SafetyLimits

__all__ = ["WorkspaceConfig", "load_workspace", "parse_workspace", "DEFAULT_TOOL_ORIENTATION"]

#: Skin facing straight down: the TCP z axis points along base -z.
DEFAULT_TOOL_ORIENTATION = (math.pi, 0.0, 0.0)

_ROBOT_KEYS = {"host", "tool_orientation", "workspace_min", "workspace_max", "limits"}
_OBJECT_KEYS = {"name", "x", "y", "surface_z", "workspace_min", "workspace_max", "slide_direction"}


@dataclass(frozen=True)
class WorkspaceConfig:
    """A robot cell: controller host, limits, tool orientation and object placements."""

    placements: dict[str, Placement]
    limits: SafetyLimits = field(default_factory=SafetyLimits)
    host: str | None = None
    tool_orientation: tuple[float, float, float] = DEFAULT_TOOL_ORIENTATION
    workspace: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    source: str = "<memory>"

    def placement(self, name: str) -> Placement:
        try:
            return self.placements[name]
        except KeyError:
            known = ", ".join(sorted(self.placements)) or "none"
            raise ConfigError(f"{self.source}: no object named {name!r} (known: {known})") from None


def load_workspace(path: str | Path) -> WorkspaceConfig:
    """Read and validate a workspace TOML file."""
    doc = read_toml(path, "a workspace file")
    return parse_workspace(doc, source=str(path))


def parse_workspace(doc: Mapping[str, Any], source: str = "<memory>") -> WorkspaceConfig:
    """Validate an already parsed document (same layout as the TOML file)."""
    unknown = set(doc) - {"robot", "object"}
    if unknown:
        raise ConfigError(
            f"{source}: unknown top-level key(s) {sorted(unknown)} (expected [robot] and [[object]])"
        )
    robot = doc.get("robot", {})
    if not isinstance(robot, Mapping):
        raise ConfigError(f"{source}: [robot] must be a table")
    unknown = set(robot) - _ROBOT_KEYS
    if unknown:
        raise ConfigError(f"{source}: [robot]: unknown key(s) {sorted(unknown)}")

    host = robot.get("host")
    if host is not None and (not isinstance(host, str) or not host.strip()):
        raise ConfigError(f"{source}: robot.host must be a non-empty string")
    orientation = DEFAULT_TOOL_ORIENTATION
    if "tool_orientation" in robot:
        rx, ry, rz = _vector(robot["tool_orientation"], 3, f"{source}: robot.tool_orientation")
        orientation = (rx, ry, rz)
    workspace = None
    if "workspace_min" in robot or "workspace_max" in robot:
        workspace = _box(robot, f"{source}: robot")
    limits = _limits(robot.get("limits", {}), source)

    objects = doc.get("object", [])
    if not isinstance(objects, list):
        raise ConfigError(f"{source}: objects must be given as [[object]] tables")
    placements: dict[str, Placement] = {}
    for i, table in enumerate(objects):
        where = f"{source}: object #{i + 1}"
        if not isinstance(table, Mapping):
            raise ConfigError(f"{where}: must be a table")
        name = table.get("name")
        if not isinstance(name, str) or not name.strip():
            raise ConfigError(f"{where}: needs a non-empty 'name'")
        where = f"{source}: object {name!r}"
        unknown = set(table) - _OBJECT_KEYS
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {sorted(unknown)}")
        if name in placements:
            raise ConfigError(f"{where}: defined twice")
        for key in ("x", "y", "surface_z", "workspace_min", "workspace_max"):
            if key not in table:
                raise ConfigError(f"{where}: missing '{key}'")
        x = _number(table["x"], f"{where}: x")
        y = _number(table["y"], f"{where}: y")
        z = _number(table["surface_z"], f"{where}: surface_z")
        lo, hi = _box(table, where)
        direction = (1.0, 0.0)
        if "slide_direction" in table:
            dx, dy = _vector(table["slide_direction"], 2, f"{where}: slide_direction")
            norm = math.hypot(dx, dy)
            if norm < 1e-9:
                raise ConfigError(f"{where}: slide_direction must not be zero")
            direction = (dx / norm, dy / norm)
        placement = Placement(name, x, y, z, lo, hi, direction)
        if not placement.contains((x, y, z)):
            raise ConfigError(
                f"{where}: the surface point ({x}, {y}, {z}) lies outside its workspace box"
            )
        if workspace is not None and not (_inside(lo, workspace) and _inside(hi, workspace)):
            raise ConfigError(f"{where}: its workspace box is not inside the robot workspace box")
        placements[name] = placement
    return WorkspaceConfig(
        placements=placements,
        limits=limits,
        host=host,
        tool_orientation=orientation,
        workspace=workspace,
        source=source,
    )


def _inside(point: tuple[float, ...], box: tuple[tuple[float, ...], tuple[float, ...]]) -> bool:
    return all(lo <= p <= hi for lo, p, hi in zip(box[0], point, box[1]))


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def _vector(value: Any, n: int, where: str) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n:
        raise ConfigError(f"{where} must be a list of {n} numbers, got {value!r}")
    return tuple(_number(v, f"{where}[{i}]") for i, v in enumerate(value))


def _box(
    table: Mapping[str, Any], where: str
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    if "workspace_min" not in table or "workspace_max" not in table:
        raise ConfigError(f"{where}: workspace_min and workspace_max go together")
    lo = _vector(table["workspace_min"], 3, f"{where}: workspace_min")
    hi = _vector(table["workspace_max"], 3, f"{where}: workspace_max")
    for axis, a, b in zip("xyz", lo, hi):
        if not a < b:
            raise ConfigError(
                f"{where}: workspace_min.{axis} ({a}) must be below workspace_max.{axis} ({b})"
            )
    return lo, hi  # type: ignore[return-value]


def _limits(table: Any, source: str) -> SafetyLimits:
    if not isinstance(table, Mapping):
        raise ConfigError(f"{source}: [robot.limits] must be a table")
    known = {f.name for f in fields(SafetyLimits)}
    unknown = set(table) - known
    if unknown:
        raise ConfigError(
            f"{source}: robot.limits: unknown key(s) {sorted(unknown)} (known: {sorted(known)})"
        )
    values = {k: _number(v, f"{source}: robot.limits.{k}") for k, v in table.items()}
    try:
        return SafetyLimits(**values)
    except ValueError as exc:
        raise ConfigError(f"{source}: robot.limits: {exc}") from None
