"""Contact models for the loopback controller: TCP pose -> normal force of the touched surface.

The simulated controller asks its contact model for the normal force at the current TCP pose
every control cycle and turns it into the TCP wrench it reports over RTDE (and that its force
mode regulates). A model is any object with

* ``normal_force(pose) -> float`` — newtons pressing the surface against the TCP (>= 0),
  ``pose`` being ``[x, y, z, rx, ry, rz]`` in the base frame (m, rotation vector);
* ``normal`` — unit vector (base frame) the surface pushes the TCP along (default +z);
* ``friction`` — optional Coulomb coefficient for the tangential force while sliding.

:class:`SpringSurface` is the simple built-in; ``{"type": "sim_object", ...}`` brings the
simulated world's indentation physics for any object of its library. Models are built inside
the controller process from a JSON-able spec (see :func:`build`), so any other model plugs in
by its import path: ``{"factory": "package.module:Class", "params": {...}}``.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

__all__ = ["ContactModel", "NoContact", "SpringSurface", "build"]


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
            raise ValueError(f"SpringSurface.stiffness must be a finite number > 0, got {self.stiffness!r}")
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise ValueError(f"SpringSurface.friction must be >= 0, got {self.friction!r}")
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


_BUILTIN = {"spring": SpringSurface, "none": NoContact}


def build(spec: Mapping[str, Any] | None) -> Any:
    """Build a contact model from a JSON-able spec.

    ``None`` or ``{"type": "none"}`` → :class:`NoContact`; ``{"type": "spring", ...fields}`` →
    :class:`SpringSurface`; ``{"type": "sim_object", "object": name, "x": .., "y": ..}`` → an
    object of the simulated world (:class:`aptkt.robot.loopback.world.SimObjectSurface`);
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
            raise ValueError(f"contact spec: unknown keys {sorted(spec)} next to 'factory'")
        module_name, _, attr = str(target).partition(":")
        if not module_name or not attr:
            raise ValueError(f"contact spec: factory must be 'module:attr', got {target!r}")
        factory = getattr(importlib.import_module(module_name), attr)
        model = factory(**params)
    else:
        kind = spec.pop("type", "spring")
        if kind == "sim_object":
            # The simulated world's contact physics (imported only when asked for).
            from aptkt.robot.loopback.world import SimObjectSurface

            return SimObjectSurface(**spec)
        if kind not in _BUILTIN:
            raise ValueError(f"contact spec: unknown type {kind!r} (known: {sorted([*_BUILTIN, 'sim_object'])})")
        model = _BUILTIN[kind](**spec)
    if not callable(getattr(model, "normal_force", None)):
        raise ValueError(f"contact model {model!r} has no normal_force(pose) method")
    return model
