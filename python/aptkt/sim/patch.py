"""The simulated skin patch: geometry of the 7 hexagonal cells and the constants of its hardware.

Patch frame: metres, x/y in the skin plane (aligned with the robot base's x/y when the skin
faces down), origin at the centre of the middle cell. Each cell carries 3 normal-force
sensors, an LM71, a BMA250 and a VCNL4010 (docs/design.md §2). Values that the paper or the
protocol do not fix are documented choices (docs/simulation.md, "The skin").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.sim.seeding import seed_sequence, spawn_generators
from aptkt.skin.protocol import PACKET_RATE_HZ, RAW_RANGES

__all__ = ["SkinConstants", "PatchGeometry", "PatchImperfections", "DEFAULT_CELL_IDS"]

#: Cell ids of the default simulated patch (any ids the wire carries but 0 and the broadcast id).
DEFAULT_CELL_IDS: tuple[int, ...] = (1, 2, 3, 4, 5, 6, 7)


@dataclass(frozen=True)
class SkinConstants:
    """Physical constants of the skin, shared by every cell. SI units."""

    rate_hz: float = PACKET_RATE_HZ  # sensor packets per cell and second
    pitch: float = 0.015  # m between neighbouring cell centres (flat-to-flat hexagon width)
    sensor_radius: float = 0.0045  # m from the cell centre to each force sensor
    # --- mechanics
    skin_stiffness: float = 1.3e6  # Pa/m: Winkler stiffness of cover + compliant mount, per area
    contact_pressure_half: float = 120.0  # Pa at which half of a cell's area is in contact
    # --- force sensors (normalised reading = offset + F / gain)
    force_gain: float = 2.5  # N per normalised unit (nominal; per-sensor values vary)
    force_offset: float = 0.20  # normalised reading at zero load (nominal)
    force_noise: float = 1.5e-3  # N rms per sensor and sample
    # --- accelerometer (BMA250)
    acc_noise: float = 0.004  # g rms per axis
    acc_bias_sd: float = 0.025  # g, zero-g offset spread between cells
    acc_bandwidth: float = 125.0  # Hz, the BMA250's digital low-pass setting
    mount_tilt_sd: float = 1.5  # degrees, how crooked each cell is glued
    # --- vibration transfer of a cell
    contact_resonance: float = 90.0  # Hz, cell mass on the contact stiffness
    contact_damping: float = 0.35  # damping ratio of that resonance
    cover_contact_length: float = 0.25e-3  # m: wavelengths shorter than this are smoothed out
    coupling_pressure: float = 150.0  # Pa: texture coupling reaches half at this contact pressure
    coupling_modulus: float = (
        0.5e6  # Pa: compliant surfaces transmit sqrt(E/(E+this)) of the motion
    )
    tangential_coupling: float = 1.2  # friction-driven tangential response relative to normal
    lateral_coupling: float = 0.35  # lateral response of obliquely oriented texture
    # --- stick-slip (spring-block with a friction drop)
    tangential_stiffness: float = 60.0  # N/m per cell
    tangential_mass: float = 0.004  # kg, effective mass of a cell in shear
    slip_coupling: float = 0.35  # share of a slip's force drop that reaches the accelerometer
    slip_ring_frequency: float = 70.0  # Hz, shear mode of the cover that a slip excites
    slip_ring_damping: float = 0.15
    slip_threshold_sd: float = 0.06  # relative spread of the static friction between events
    # --- thermal (per cell)
    heater_power: float = 0.40  # W dissipated by the cell's electronics
    pcb_capacity: float = 0.30  # J/K
    back_conductance: float = 0.070  # W/K to the mount and the air behind the cell
    cover_thickness: float = 1.0e-3  # m, elastomer cover
    cover_conductivity: float = 0.25  # W/(m K)
    cover_heat_capacity: float = 1.5e6  # J/(m^3 K)
    air_transfer: float = 10.0  # W/(m^2 K), free convection on an exposed face
    lm71_lag: float = 0.6  # s, first-order lag of the LM71 behind the PCB
    die_self_heating: float = 1.5  # K, accelerometer die above the PCB
    temp_noise: float = 0.012  # °C rms (LM71)
    die_temp_noise: float = 0.15  # °C rms (accelerometer die)
    # --- proximity (VCNL4010)
    prox_dark: float = 0.03  # reading with nothing in front
    prox_gain: float = 0.55  # reading added by a perfect reflector at zero distance
    prox_distance: float = 0.004  # m, distance at which the reflection falls to half
    prox_noise: float = 1.0e-3
    table_reflectivity: float = 0.3
    # --- packet timing
    clock_tolerance: float = 2e-3  # relative spread of the cells' sample rates
    link_latency: float = 0.8e-3  # s from sampling to arrival on the PC
    link_jitter: float = 0.6e-3  # s, uniform extra arrival delay

    @property
    def cell_area(self) -> float:
        """Area of one hexagonal cell (flat-to-flat width = pitch)."""
        return math.sqrt(3.0) / 2.0 * self.pitch**2

    @property
    def sensor_area(self) -> float:
        """Area carried by one force sensor (a third of the cell)."""
        return self.cell_area / 3.0


@dataclass(frozen=True)
class PatchGeometry:
    """Where the cells and their force sensors are in the patch frame (metres).

    ``centres`` default to the nominal patch: the middle cell, then six neighbours
    counter-clockwise from +x at one pitch (the layout of the skin's default patch file).
    """

    cell_ids: tuple[int, ...] = DEFAULT_CELL_IDS
    constants: SkinConstants = field(default_factory=SkinConstants)
    centres: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        ids = tuple(int(c) for c in self.cell_ids)
        object.__setattr__(self, "cell_ids", ids)
        ((_, broadcast),) = RAW_RANGES["cell_id"]
        if not ids or len(set(ids)) != len(ids) or not all(0 < c < broadcast for c in ids):
            raise InvalidInputError(f"cell ids must be distinct, in 1..{broadcast - 1}, got {ids}")
        if not self.centres:
            p = self.constants.pitch
            ring = [
                (p * math.cos(math.radians(60 * i)), p * math.sin(math.radians(60 * i)))
                for i in range(6)
            ]
            nominal = [(0.0, 0.0), *ring]
            if len(ids) > len(nominal):
                raise InvalidInputError(f"give cell centres for a patch of {len(ids)} cells")
            object.__setattr__(self, "centres", tuple(nominal[: len(ids)]))
        if len(self.centres) != len(ids):
            raise InvalidInputError(f"{len(ids)} cell ids but {len(self.centres)} centres")

    @classmethod
    def from_patch(
        cls,
        cell_ids: tuple[int, ...],
        positions_mm: np.ndarray,
        constants: SkinConstants | None = None,
    ) -> PatchGeometry:
        """From a skin patch description (ids and positions in millimetres)."""
        pos = np.asarray(positions_mm, dtype=np.float64).reshape(len(cell_ids), -1)[:, :2] * 1e-3
        return cls(tuple(cell_ids), constants or SkinConstants(), tuple(map(tuple, pos.tolist())))

    @property
    def n_cells(self) -> int:
        return len(self.cell_ids)

    @property
    def cell_centres(self) -> np.ndarray:
        """(n, 2) cell centres."""
        return np.array(self.centres, dtype=np.float64)

    @property
    def sensor_positions(self) -> np.ndarray:
        """(n, 3, 2): the three force sensors of each cell at 90°, 210°, 330°."""
        r = self.constants.sensor_radius
        ang = np.deg2rad(np.array([90.0, 210.0, 330.0]))
        local = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
        return self.cell_centres[:, None, :] + local[None, :, :]

    @property
    def extent(self) -> float:
        """Radius of the patch (centre to the outermost cell corner)."""
        reach = float(np.max(np.hypot(*self.cell_centres.T)))
        return reach + self.constants.pitch / math.sqrt(3.0)


@dataclass(frozen=True)
class PatchImperfections:
    """How this particular patch deviates from nominal; fixed for a patch (its own seed).

    The calibration the PC holds (``believed_*``) differs from the sensors' true response by
    a few percent, as after any real calibration.
    """

    force_gain: np.ndarray  # (n, 3) true N per normalised unit
    force_offset: np.ndarray  # (n, 3) true zero-load reading
    believed_gain: np.ndarray  # (n, 3) calibration: N per normalised unit
    believed_offset: np.ndarray  # (n, 3) calibration: zero-load reading
    sensor_height: np.ndarray  # (n, 3) m, sensor recessed (+) or proud (-) of the skin plane
    acc_bias: np.ndarray  # (n, 3) g
    mount_rotation: np.ndarray  # (7, 3, 3) accelerometer axes in the patch frame (columns)
    clock_rate: np.ndarray  # (7,) Hz, actual sample rate of each cell
    clock_phase: np.ndarray  # (7,) s, time of each cell's first sample after t = 0

    @classmethod
    def generate(
        cls, constants: SkinConstants, n_cells: int = 7, seed: int = 0
    ) -> PatchImperfections:
        n = int(n_cells)
        g = spawn_generators(seed_sequence(seed, "patch"), ["force", "height", "acc", "clock"])
        rng = g["force"]
        gain = constants.force_gain * (1.0 + 0.08 * rng.standard_normal((n, 3)))
        offset = constants.force_offset + 0.03 * rng.standard_normal((n, 3))
        believed_gain = gain * (1.0 + 0.02 * rng.standard_normal((n, 3)))
        believed_offset = offset + 0.002 * rng.standard_normal((n, 3))
        height = 15e-6 * g["height"].standard_normal((n, 3))
        rng = g["acc"]
        bias = constants.acc_bias_sd * rng.standard_normal((n, 3))
        rot = np.empty((n, 3, 3))
        for c in range(n):
            tilt = np.deg2rad(constants.mount_tilt_sd) * rng.standard_normal(2)
            yaw = np.deg2rad(2.0) * rng.standard_normal()
            rot[c] = _rotation(tilt[0], tilt[1], yaw)
        rng = g["clock"]
        rate = constants.rate_hz * (1.0 + constants.clock_tolerance * rng.uniform(-1.0, 1.0, n))
        phase = rng.uniform(0.0, 1.0, n) / rate
        return cls(gain, offset, believed_gain, believed_offset, height, bias, rot, rate, phase)


def _rotation(rx: float, ry: float, rz: float) -> np.ndarray:
    """Rotation matrix for small tilts rx, ry and a yaw rz (radians), R = Rz Ry Rx."""
    cx, sx, cy, sy, cz, sz = (
        math.cos(rx),
        math.sin(rx),
        math.cos(ry),
        math.sin(ry),
        math.cos(rz),
        math.sin(rz),
    )
    r_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    r_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    r_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return r_z @ r_y @ r_x
