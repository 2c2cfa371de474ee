"""Contact physics of the simulated world as a loopback contact model.

An object of the simulated world's library (:mod:`aptkt.sim.objects`) lies with its top face
centred at ``(x, y)``; the nominal 7-cell patch presses on it with its skin plane at the TCP.
Each of the 21 force sensors carries the pressure of the world's indentation law
(:class:`aptkt.sim.mechanics.IndentationLaw`: skin compliance and the object's layers in series)
at its local depth below the object's face (:class:`aptkt.sim.mechanics.SurfaceShape`: crown,
waviness, footprint); the normal force is their sum times the sensor area, as in the world.

For the loopback's simulated skin it also gives the object's thermal description (its layers
and contact conductance, :meth:`SimObjectSurface.thermal_contact`) and the vibration its
texture excites in the cells while sliding (:meth:`SimObjectSurface.texture_acceleration`, the
world's texture model without its stick-slip).

What the loopback leaves out, because its contact model sees only the current pose: the
viscoelastic relaxation (it needs the indentation history), the stick-slip, the per-trial
variations and the patch's imperfections. Those stay in :mod:`aptkt.sim`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from aptkt.sim.loopback.thermal_contact import ThermalContact
from aptkt.sim.mechanics import IndentationLaw, SurfaceShape
from aptkt.sim.objects import default_library, load_library
from aptkt.sim.patch import PatchGeometry, SkinConstants
from aptkt.sim.texture import texture_acceleration, texture_field, waviness_waves

__all__ = ["SimObjectSurface"]


class SimObjectSurface:
    """Normal force of a simulated-world object pressed by the nominal skin patch.

    ``surface_z`` defaults to the object's height (it lies on the table at z = 0);
    ``library_files`` adds objects files to the default library.
    """

    normal = (0.0, 0.0, 1.0)

    def __init__(
        self,
        object: str,
        x: float,
        y: float,
        surface_z: float | None = None,
        rotation: float = 0.0,
        library_files: Sequence[str] = (),
    ):
        library = load_library(*library_files) if library_files else default_library()
        spec = library[object]
        constants = SkinConstants()
        self.object_name = spec.name
        self.law = IndentationLaw(spec.layers, constants.skin_stiffness)
        self.shape = SurfaceShape(
            centre=(float(x), float(y)),
            rotation=float(rotation),
            surface_z=float(spec.height if surface_z is None else surface_z),
            tilt=(0.0, 0.0),
            crown_radius=spec.crown_radius,
            waves=waviness_waves(spec),
            size=spec.size,
        )
        self.sensor_offsets = PatchGeometry(constants=constants).sensor_positions  # (7, 3, 2)
        self.sensor_area = constants.sensor_area
        self.friction = spec.surface.friction_kinetic
        self.constants = constants
        self.spec = spec
        self.texture = texture_field(spec)

    def sensor_forces(self, pose: Sequence[float]) -> np.ndarray:
        """(7, 3) newtons on each force sensor with the skin plane at ``pose``."""
        xy = np.asarray(pose[:2], dtype=np.float64) + self.sensor_offsets
        depth = self.shape.height(xy) - float(pose[2])
        return self.law.stress(np.where(np.isfinite(depth), depth, -1.0)) * self.sensor_area

    def normal_force(self, pose: Sequence[float]) -> float:
        return float(self.sensor_forces(pose).sum())

    def thermal_contact(self, pose: Sequence[float]) -> ThermalContact:
        """The object's layers and surface, for the skin's heat exchange."""
        return ThermalContact(
            self.spec.name,
            tuple(self.spec.layers),
            float(self.spec.surface.contact_conductance),
            float(self.spec.temperature_offset),
        )

    def texture_acceleration(
        self, cell_xy: np.ndarray, velocity: np.ndarray, pressure: np.ndarray
    ) -> np.ndarray:
        """Texture vibration (n, 3) in m/s^2, base frame, of cells at ``cell_xy`` (n, 2) moving
        at ``velocity`` (base frame, m/s) under mean contact pressure ``pressure`` (n,) Pa."""
        xy = np.asarray(cell_xy, dtype=np.float64)
        v = np.asarray(velocity, dtype=np.float64)[:2]
        u = self.shape.to_object(xy)
        w = np.broadcast_to(self.shape.to_object_direction(v), u.shape)
        tex = texture_acceleration(
            self.texture,
            self.constants,
            u,
            w,
            np.asarray(pressure, dtype=np.float64),
            self.spec.top.modulus,
            self.spec.surface.friction_kinetic,
        )
        speed = float(np.hypot(v[0], v[1]))
        direction = v / speed if speed > 1e-9 else np.array([1.0, 0.0])
        lateral = np.array([-direction[1], direction[0]])
        out = np.zeros_like(tex)
        out[:, :2] = tex[:, 0:1] * direction + tex[:, 1:2] * lateral
        out[:, 2] = tex[:, 2]
        return out
