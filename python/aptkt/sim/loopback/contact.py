"""Contact models for the loopback controller: TCP pose -> normal force of the touched surface.

The simulated controller asks its contact model for the normal force at the current TCP pose
every control cycle and turns it into the TCP wrench it reports over RTDE (and that its force
mode regulates). A model is any object with

* ``normal_force(pose) -> float`` — newtons pressing the surface against the TCP (>= 0),
  ``pose`` being ``[x, y, z, rx, ry, rz]`` in the base frame (m, rotation vector);
* ``normal`` — unit vector (base frame) the surface pushes the TCP along (default +z);
* ``friction`` — optional Coulomb coefficient for the tangential force while sliding.

The loopback's simulated skin (:mod:`aptkt.sim.loopback.tcp_skin`) also uses, when a model has
them:

* ``sensor_forces(pose) -> (7, 3)`` — newtons on each force sensor of the nominal 7-cell patch
  (without it, the normal force is shared equally by all sensors);
* ``thermal_contact(pose) -> ThermalContact | None`` — what the skin touches, thermally
  (without it, a generic wooden block);
* ``texture_acceleration(cell_xy, velocity, pressure) -> (n, 3)`` — the texture's vibration at
  the cells while sliding (without it, none).

:class:`SpringSurface` is the simple built-in; ``{"type": "sim_object", ...}`` brings the
simulated world's indentation physics for any object of its library; ``{"type": "scene",
"items": [...]}`` puts several models side by side (:class:`Scene`), and ``{"type":
"workspace", "file": ...}`` builds a scene from a workspace file (:func:`scene_from_workspace`).
Models are built inside the controller process from a JSON-able spec (see :func:`build`), so
any other model plugs in by its import path: ``{"factory": "package.module:Class", "params": {...}}``.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.robot.workspace import load_workspace
from aptkt.sim.loopback.object_surface import SimObjectSurface
from aptkt.sim.loopback.thermal_contact import ThermalContact
from aptkt.sim.objects import default_library, load_library

__all__ = [
    "ContactModel",
    "NoContact",
    "SpringSurface",
    "Scene",
    "ThermalContact",
    "build",
    "scene_from_workspace",
]


@runtime_checkable
class ContactModel(Protocol):
    normal: tuple[float, float, float]

    def normal_force(self, pose: Sequence[float]) -> float: ...


@dataclass(frozen=True)
class NoContact:
    """Free space: the TCP never touches anything."""

    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    friction: float = 0.0

    def normal_force(self, pose: Sequence[float]) -> float:
        return 0.0


@dataclass(frozen=True)
class SpringSurface:
    """A flat horizontal surface at ``surface_z`` that pushes back like a linear spring.

    The force is ``stiffness * (surface_z - z)`` where the TCP is below the surface and within
    the optional ``x_range``/``y_range`` footprint, else 0. ``stiffness`` lumps skin and object
    together (N/m); the default (200 N/m) gives 0.2 N at 1 mm, the order of the paper's presses.
    """

    surface_z: float = 0.0
    stiffness: float = 200.0
    friction: float = 0.0
    x_range: tuple[float, float] | None = None
    y_range: tuple[float, float] | None = None
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.stiffness) and self.stiffness > 0):
            raise InvalidInputError(
                f"SpringSurface.stiffness must be a finite number > 0, got {self.stiffness!r}"
            )
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise InvalidInputError(f"SpringSurface.friction must be >= 0, got {self.friction!r}")
        # JSON brings ranges as lists; keep the dataclass hashable and comparable.
        for name in ("x_range", "y_range"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, (float(value[0]), float(value[1])))
        object.__setattr__(self, "normal", tuple(float(v) for v in self.normal))

    def normal_force(self, pose: Sequence[float]) -> float:
        x, y, z = float(pose[0]), float(pose[1]), float(pose[2])
        if self.x_range is not None and not self.x_range[0] <= x <= self.x_range[1]:
            return 0.0
        if self.y_range is not None and not self.y_range[0] <= y <= self.y_range[1]:
            return 0.0
        depth = self.surface_z - z
        return self.stiffness * depth if depth > 0 else 0.0


class Scene:
    """Several contact models side by side (objects on a table): forces add up; friction,
    heat and texture come from the item that carries the most force at the last pose asked
    about. Items must not overlap (where they do, their forces would add)."""

    def __init__(self, items: Sequence[Any]):
        self.items = list(items)
        if not self.items:
            raise InvalidInputError("a scene needs at least one contact model")
        normals = {
            tuple(float(v) for v in getattr(m, "normal", (0.0, 0.0, 1.0))) for m in self.items
        }
        if len(normals) != 1:
            raise InvalidInputError(
                f"the items of a scene must share one surface normal, got {sorted(normals)}"
            )
        self.normal = normals.pop()
        self._active = 0

    def _forces(self, pose: Sequence[float]) -> list[float]:
        forces = [float(m.normal_force(pose)) for m in self.items]
        best = max(range(len(forces)), key=forces.__getitem__)
        if forces[best] > 0:
            self._active = best
        return forces

    @property
    def active(self) -> Any:
        """The item last found in contact (the first item before any contact)."""
        return self.items[self._active]

    @property
    def friction(self) -> float:
        return float(getattr(self.active, "friction", 0.0) or 0.0)

    def normal_force(self, pose: Sequence[float]) -> float:
        return float(sum(self._forces(pose)))

    def sensor_forces(self, pose: Sequence[float]) -> np.ndarray:
        total = np.zeros((7, 3))
        for model, force in zip(self.items, self._forces(pose)):
            if force <= 0:
                continue
            if callable(getattr(model, "sensor_forces", None)):
                total += model.sensor_forces(pose)
            else:
                total += force / 21.0
        return total

    def thermal_contact(self, pose: Sequence[float]) -> ThermalContact | None:
        self._forces(pose)
        method = getattr(self.active, "thermal_contact", None)
        return method(pose) if callable(method) else None

    def texture_acceleration(
        self, cell_xy: np.ndarray, velocity: np.ndarray, pressure: np.ndarray
    ) -> np.ndarray:
        method = getattr(self.active, "texture_acceleration", None)
        if not callable(method):
            return np.zeros((len(pressure), 3))
        return method(cell_xy, velocity, pressure)


def scene_from_workspace(
    path: str, *, stiffness: float = 200.0, friction: float = 0.3, library_files: Sequence[str] = ()
) -> dict[str, Any]:
    """A scene spec that puts an object at every placement of a workspace file.

    An object whose name is in the simulated world's library becomes that object
    (``sim_object``) with its top face at the placement's ``surface_z``; any other name becomes
    a spring surface (``stiffness``, ``friction``) at ``surface_z`` over the x/y footprint of
    the placement's workspace box. So one workspace file describes both the loopback's world
    and the cell that ``aptkt collect --robot ur10`` explores.
    """

    config = load_workspace(path)
    library = load_library(*library_files) if library_files else default_library()
    items: list[dict[str, Any]] = []
    for name, p in config.placements.items():
        if name in library:
            items.append(
                {
                    "type": "sim_object",
                    "object": name,
                    "x": p.x,
                    "y": p.y,
                    "surface_z": p.surface_z,
                    "library_files": list(library_files),
                }
            )
        else:
            items.append(
                {
                    "type": "spring",
                    "surface_z": p.surface_z,
                    "stiffness": stiffness,
                    "friction": friction,
                    "x_range": [p.workspace_min[0], p.workspace_max[0]],
                    "y_range": [p.workspace_min[1], p.workspace_max[1]],
                }
            )
    if not items:
        raise InvalidInputError(f"{path}: the workspace file places no objects")
    return {"type": "scene", "items": items}


_BUILTIN = {"spring": SpringSurface, "none": NoContact}


def build(spec: Mapping[str, Any] | None) -> Any:
    """Build a contact model from a JSON-able spec.

    ``None`` or ``{"type": "none"}`` → :class:`NoContact`; ``{"type": "spring", ...fields}`` →
    :class:`SpringSurface`; ``{"type": "sim_object", "object": name, "x": .., "y": ..}`` → an
    object of the simulated world (:class:`aptkt.sim.loopback.object_surface.SimObjectSurface`);
    ``{"factory": "module:attr", "params": {...}}`` → ``attr(**params)`` for any model
    importable in the controller process.
    """
    if spec is None:
        return NoContact()
    spec = dict(spec)
    if "factory" in spec:
        target = spec.pop("factory")
        params = spec.pop("params", {}) or {}
        if spec:
            raise InvalidInputError(f"contact spec: unknown keys {sorted(spec)} next to 'factory'")
        module_name, _, attr = str(target).partition(":")
        if not module_name or not attr:
            raise InvalidInputError(f"contact spec: factory must be 'module:attr', got {target!r}")
        factory = getattr(importlib.import_module(module_name), attr)
        model = factory(**params)
    else:
        kind = spec.pop("type", "spring")
        if kind == "scene":
            items = spec.pop("items", None)
            if spec or not isinstance(items, list):
                raise InvalidInputError(
                    "contact spec: a scene is {'type': 'scene', 'items': [spec, ...]}"
                )
            return Scene([build(item) for item in items])
        if kind == "workspace":
            if "file" not in spec:
                raise InvalidInputError("contact spec: a workspace scene needs 'file'")
            return build(scene_from_workspace(spec.pop("file"), **spec))
        if kind == "sim_object":
            # The simulated world's contact physics (imported only when asked for).

            return SimObjectSurface(**spec)
        if kind not in _BUILTIN:
            raise InvalidInputError(
                f"contact spec: unknown type {kind!r} "
                f"(known: {sorted([*_BUILTIN, 'sim_object', 'scene', 'workspace'])})"
            )
        model = _BUILTIN[kind](**spec)
    if not callable(getattr(model, "normal_force", None)):
        raise InvalidInputError(f"contact model {model!r} has no normal_force(pose) method")
    return model
