"""The contact physics of one trial: from the TCP's motion to every sensor value of every cell.

:class:`ContactPhysics` is a pure step function, ``step(state, trajectory, t_end) -> (state',
frames, force trace)``: it produces every cell's samples whose sample time falls in
``(state.t, t_end]``. Because every stateful part is integrated exactly at the sample times and
all randomness is addressed by (cell, sample index), the output does not depend on how a
motion is cut into steps, and a step can be undone by keeping the old state (the simulated
robot uses that to stop exactly where a safety limit is crossed).

Units: SI inside; frames carry the protocol's physical units (g, °C, normalised force).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt import _core
from aptkt._core import MechChunk, PhysicsState
from aptkt.errors import InvalidInputError
from aptkt.sim.kinematics import Trajectory
from aptkt.sim.mechanics import IndentationLaw, SurfaceShape
from aptkt.sim.objects import ObjectSpec, Relaxation
from aptkt.sim.patch import PatchGeometry, PatchImperfections
from aptkt.sim.seeding import CounterStream
from aptkt.sim.texture import StickSlip, texture_field, waviness_waves
from aptkt.sim.thermal import (
    CONTACT_STEPS,
    SPEED_STEP,
    CellThermal,
    ThermalNetwork,
    interface_level,
)
from aptkt.sim.trial import TrialConditions

__all__ = [
    "GRAVITY",
    "Frames",
    "ForceTrace",
    "MechChunk",
    "PhysicsState",
    "ContactPhysics",
    "ObjectPose",
]

GRAVITY = 9.80665
#: Cell accelerometer axes in the base frame for a skin facing down: x along base x, z out of
#: the skin (base -z), y completing a right-handed frame.
_FLIP = np.diag([1.0, -1.0, -1.0])
#: Random words per sample: 10 → 10 normals (force 3, acc 3, temp 2, proximity 1, spare 1),
#: 1 uniform (arrival jitter), 1 spare.
_NOISE_SLOTS = 12
#: Key of (cell, sample time) pairs in one int64: sample times stay far below 2^52 ns (52 days).
_KEY = np.int64(1 << 52)


@dataclass(frozen=True)
class ObjectPose:
    """Where the object's top face nominally is (the trial adds its own shift and turn)."""

    centre: tuple[float, float]
    surface_z: float
    rotation: float  # rad


@dataclass
class Frames:
    """Sensor samples of all cells in arrival order, in physical units."""

    cell_index: np.ndarray  # (n,) position of the cell in the patch
    cell_id: np.ndarray  # (n,)
    t_sample_ns: np.ndarray  # (n,)
    t_ns: np.ndarray  # (n,) arrival time on the PC
    proximity: np.ndarray  # (n,)
    acc: np.ndarray  # (n, 3) g
    temp: np.ndarray  # (n, 2) °C: accelerometer die, LM71
    force: np.ndarray  # (n, 3) normalised reading (offset + F / gain)
    force_true: np.ndarray  # (n,) N, true normal force on the cell

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    @classmethod
    def empty(cls) -> Frames:
        z = np.zeros
        return cls(
            z(0, np.int64),
            z(0, np.int64),
            z(0, np.int64),
            z(0, np.int64),
            z(0),
            z((0, 3)),
            z((0, 2)),
            z((0, 3)),
            z(0),
        )

    def take(self, index: np.ndarray | slice) -> Frames:
        return Frames(**{k: getattr(self, k)[index] for k in self.__dataclass_fields__})


@dataclass
class ForceTrace:
    """True normal force of every sample (also those not turned into frames), cell-major:
    what the robot's own wrench sensing sees."""

    cell_index: np.ndarray  # (m,)
    t_sample_ns: np.ndarray  # (m,)
    force: np.ndarray  # (m,) N on the cell

    @classmethod
    def empty(cls) -> ForceTrace:
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))

    def total_at(self, ticks_ns: np.ndarray, latest: np.ndarray) -> np.ndarray:
        """Total force at each tick: every cell's newest sample at or before the tick (``latest``
        holds each cell's force before this trace)."""
        ticks_ns = np.asarray(ticks_ns, dtype=np.int64)
        n_cells = latest.shape[0]
        if not self.force.size:
            values = np.broadcast_to(latest[:, None], (n_cells, ticks_ns.shape[0]))
        else:
            values = self._values_at(ticks_ns, latest)
        total = np.zeros(ticks_ns.shape[0])
        for row in values:  # cell by cell, in the order the robot's sensing adds them
            total += row
        return total

    def _values_at(self, ticks_ns: np.ndarray, latest: np.ndarray) -> np.ndarray:
        """(cells, ticks): each cell's newest force at or before each tick."""
        n_cells = latest.shape[0]
        # One search for every (cell, tick): the trace is cell-major and time-ordered within a
        # cell, so (cell, time) pairs sort as one key.
        cells = np.arange(n_cells)
        starts = np.searchsorted(self.cell_index, cells, side="left")
        idx = (
            np.searchsorted(
                self.cell_index * _KEY + self.t_sample_ns,
                (cells[:, None] * _KEY + ticks_ns[None, :]).ravel(),
                side="right",
            ).reshape(n_cells, -1)
            - 1
        )
        found = idx >= starts[:, None]
        return np.where(found, self.force[np.maximum(idx, 0)], latest[:, None])


class ContactPhysics:
    """Physics of one object in one trial against the simulated patch."""

    def __init__(
        self,
        obj: ObjectSpec,
        pose: ObjectPose,
        conditions: TrialConditions,
        geometry: PatchGeometry,
        imperfections: PatchImperfections,
        noise_seq: np.random.SeedSequence,
    ):
        self.obj, self.cond, self.geo, self.imp = obj, conditions, geometry, imperfections
        k = self.k = geometry.constants
        self.n = n = geometry.n_cells
        self.law = IndentationLaw(
            obj.layers, k.skin_stiffness * conditions.skin_stiffness_scale, conditions.modulus_scale
        )
        weights = tuple(w * conditions.relaxation_scale for w in obj.relaxation.weights)
        if weights and sum(weights) > 0.95:  # keep the long-term stiffness positive
            weights = tuple(w * 0.95 / sum(weights) for w in weights)
        self.relaxation = Relaxation(weights, obj.relaxation.times)
        self.shape = SurfaceShape(
            centre=(pose.centre[0] + conditions.shift[0], pose.centre[1] + conditions.shift[1]),
            rotation=pose.rotation + conditions.rotation,
            surface_z=pose.surface_z,
            tilt=conditions.tilt,
            crown_radius=obj.crown_radius,
            waves=waviness_waves(obj),
            size=obj.size,
        )
        # The cover's coupling scales everything that reaches the accelerometers through it:
        # the texture's accelerations (linear in the surface's amplitudes) and the slips' ringing.
        self.texture = texture_field(obj).scaled(
            conditions.roughness_scale * conditions.texture_coupling
        )
        self.mu_k = obj.surface.friction_kinetic * conditions.friction_scale
        self.top_modulus = obj.top.modulus * conditions.modulus_scale
        self.thermal = CellThermal(
            k,
            obj.layers,
            obj.surface.contact_conductance * interface_level(conditions.interface_scale),
            conditions.ambient,
            conditions.object_temperature,
            conditions.conductance_scale,
        )
        mu_s = obj.surface.friction_static * conditions.friction_scale
        slip_constants = dataclasses.replace(
            k, slip_coupling=k.slip_coupling * conditions.texture_coupling
        )
        self.slip = StickSlip(slip_constants, mu_s, self.mu_k, _child(noise_seq, 1), n)
        self._noise = CounterStream(_child(noise_seq, 2), _NOISE_SLOTS)
        self._sensor_xy = geometry.sensor_positions  # (C, 3, 2)
        self._centres = geometry.cell_centres  # (C, 2)
        # Cell axes in base: _FLIP @ R for each cell, written as the row signs it is (a 3 × 3
        # product per cell would wake BLAS's threads, which then spin for a while).
        self._axes = (
            np.asarray(imperfections.mount_rotation, dtype=np.float64)[:n]
            * np.diag(_FLIP)[None, :, None]
        )
        self.cell_ids = np.asarray(geometry.cell_ids, dtype=np.int64)
        self._latency_ns = int(round(k.link_latency * 1e9))
        self._gain_drift = np.asarray(
            conditions.force_gain_drift, dtype=np.float64
        )  # > 1: reads high
        if self._gain_drift.shape != (n,):
            raise InvalidInputError(
                f"trial conditions are for {self._gain_drift.size} cells, the patch has {n}"
            )
        #: The sensors' zero-load readings in this trial: the patch's own, moved by the zero's
        #: drift (a force error in N, read through each sensor's true gain).
        self._offset = np.asarray(imperfections.force_offset, dtype=np.float64)[:n] + np.asarray(
            conditions.force_offset, dtype=np.float64
        ).reshape(n, 3) / (np.asarray(imperfections.force_gain)[:n] / self._gain_drift[:, None])
        #: How the skin's accelerometers respond to this object's texture (the compiled core's
        #: settings; also what ``aptkt._core.sim_texture`` takes).
        self.texture_response = _core.TextureResponse(
            _core.ContactVibration(
                k.cover_contact_length, k.contact_resonance, k.contact_damping, k.acc_bandwidth
            ),
            _core.TextureCoupling(
                k.coupling_modulus, k.coupling_pressure, k.tangential_coupling, k.lateral_coupling
            ),
            float(self.top_modulus),
            float(self.mu_k),
        )
        #: The compiled core of this trial: mechanics, force-control ticks and every reading
        #: (heat, stick-slip, texture, noise). The thermal solution operators of each
        #: (contact, speed) configuration it meets come from the object's network: made by
        #: ``ThermalNetwork.system`` and kept, converted, in ``ThermalNetwork.core``.
        self.core = self._compile()

    def _compile(self) -> _core.SimContact:
        """The compiled core from this trial's settings, one object per core struct."""
        k, imp, shape = self.k, self.imp, self.shape
        return _core.SimContact(
            self._patch_cells(),
            _core.SurfaceShape(
                _pair(shape.centre),
                float(shape.rotation),
                float(shape.surface_z),
                _pair(shape.tilt),
                float(shape.crown_radius),
                np.reshape(shape.waves, (-1, 4)).tolist(),
                _pair(shape.size),
            ),
            _core.ContactLaw(
                self.law.table[0].tolist(),
                self.law.table[1].tolist(),
                self.law.skin_stiffness,
                [float(w) for w in self.relaxation.weights],
                [float(t) for t in self.relaxation.times],
                float(k.sensor_area),
            ),
            _core.ForceSensors(
                (int(self._noise.key[0]), int(self._noise.key[1])),
                (imp.force_gain / self._gain_drift[:, None]).tolist(),
                self._offset.tolist(),
                float(k.force_noise),
                self._latency_ns,
                float(k.link_jitter),
            ),
            _core.Surface(
                _core.TextureField(
                    self.texture.kvec.tolist(),
                    self.texture.amplitude.tolist(),
                    self.texture.phase.tolist(),
                ),
                self.texture_response,
                self.slip.params,
                [s.key for s in self.slip._streams],
            ),
            self._readout(),
            _core.ThermalContact(
                self.thermal.net.core,
                # Not a bound method of self: the core must not keep this object alive.
                functools.partial(_object_system, self.thermal.net),
                np.sqrt(self.thermal.net.cap).tolist(),
                float(k.heater_power),
                self.thermal.ambient,
                self.thermal.object_temperature,
            ),
        )

    def _patch_cells(self) -> _core.PatchCells:
        imp = self.imp
        return _core.PatchCells(
            np.asarray(imp.clock_rate, dtype=np.float64).tolist(),
            np.asarray(imp.clock_phase, dtype=np.float64).tolist(),
            np.asarray(imp.sensor_height, dtype=np.float64).tolist(),
            np.asarray(self._sensor_xy, dtype=np.float64).tolist(),
        )

    def _readout(self) -> _core.Readout:
        k, cond = self.k, self.cond
        return _core.Readout(
            _core.CellFrames(
                np.asarray(self._centres, dtype=np.float64).tolist(),
                self._axes.tolist(),
                np.asarray(self.imp.acc_bias, dtype=np.float64).tolist(),
                self.cell_ids.tolist(),
            ),
            _core.Accelerometers(
                GRAVITY, k.acc_noise, cond.arm_vibration, [list(m) for m in cond.arm_modes]
            ),
            _core.Thermometers(k.die_self_heating, k.die_temp_noise, k.temp_noise),
            _core.Proximity(
                k.prox_dark,
                k.prox_gain,
                k.prox_distance,
                k.prox_noise,
                self.obj.reflectivity,
                k.table_reflectivity,
            ),
            _core.ContactHeat(
                k.contact_pressure_half,
                self.thermal.conductance_scale,
                float(CONTACT_STEPS),
                SPEED_STEP,
            ),
        )

    # ---------------------------------------------------------------------------------------
    def initial_state(self, t_ns: int, position: np.ndarray) -> PhysicsState:
        """At rest at ``position`` (out of contact), skin in its steady state plus the trial's offset."""
        start = self.thermal.initial_state(self.cond.skin_offset)
        t_s = t_ns * 1e-9
        next_k = [
            max(0, math.floor((t_s - self.imp.clock_phase[c]) * self.imp.clock_rate[c]) + 1)
            for c in range(self.n)
        ]
        last_xy = np.asarray(position[:2], dtype=np.float64) + self._centres
        return self.core.rest_state(
            int(t_ns),
            [int(k) for k in next_k],
            np.asarray(start, dtype=np.float64).tolist(),
            last_xy.tolist(),
        )

    def step(
        self, state: PhysicsState, traj: Trajectory, t_end_ns: int, *, detail: bool = True
    ) -> tuple[PhysicsState, Frames, ForceTrace]:
        """Advance to ``t_end_ns``: the new state, the frames (arrival order) and the true force of
        every sample. With ``detail=False`` only each cell's newest sample becomes a frame (the
        state is integrated exactly all the same)."""
        st = state.copy()
        frames, trace = self.core.step(st, traj.segments(), int(t_end_ns), detail)
        return st, Frames(**frames), ForceTrace(**trace)

    def mechanics(self, st: PhysicsState, traj: Trajectory, t_end_ns: int) -> MechChunk:
        """First half of a step (updates ``st`` in place): the samples due by ``t_end_ns``, the TCP
        motion at their times and the contact stress at every force sensor, with relaxation
        (the per-sample loop runs in the compiled core, ``aptkt_sim::mechanics``)."""
        return self.core.mechanics(st, traj.segments(), int(t_end_ns))

    def finish(
        self, st: PhysicsState, chunk: MechChunk, *, detail: bool = True
    ) -> tuple[Frames, ForceTrace]:
        """Second half of a step: heat, stick-slip, texture, sensor noise and readings for the
        samples of ``chunk`` (which must follow ``st``'s non-mechanical state; ``aptkt_sim::
        readout``, docs/simulation.md "Cost")."""
        if chunk.size == 0:
            return Frames.empty(), ForceTrace.empty()
        frames, trace = self.core.finish(st, chunk, detail)
        return Frames(**frames), ForceTrace(**trace)

    def _noise_and_arrival(
        self, ks: np.ndarray, cells: np.ndarray, t_ns: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Normal deviates (n, 10) and arrival times of samples ``ks`` of ``cells``."""
        return self.core.noise(
            np.ascontiguousarray(ks, dtype=np.int64),
            np.ascontiguousarray(cells, dtype=np.int64),
            np.ascontiguousarray(t_ns, dtype=np.int64),
        )

    def _force_reading(
        self, f_true: np.ndarray, noise: np.ndarray, cells: np.ndarray
    ) -> np.ndarray:
        """Normalised force readings (offset + (F + noise) / gain) of the sensors of ``cells``."""
        imp = self.imp
        gain = imp.force_gain[cells] / self._gain_drift[cells][:, None]
        return self._offset[cells] + (f_true + self.k.force_noise * noise[:, 0:3]) / gain

    def force_readings(self, chunk: MechChunk) -> tuple[np.ndarray, np.ndarray]:
        """Arrival times and normalised force readings (n, 3) of every sample of ``chunk``: the
        force part of the packets :meth:`finish` will produce, for a controller that needs it
        before the rest of the packets is computed."""
        cells = chunk.cells
        noise, arrival = self._noise_and_arrival(chunk.ks, cells, chunk.t_ns)
        return arrival, self._force_reading(chunk.sigma * self.k.sensor_area, noise, cells)


def _runs(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First and last index of each cell's block in a cell-major array, and the cells present."""
    bounds = np.flatnonzero(np.diff(cells)) + 1
    first = np.concatenate([[0], bounds])
    last = np.concatenate([bounds - 1, [cells.size - 1]])
    return first, last, cells[first]


def _object_system(net: ThermalNetwork, phi_bin: int, speed_bin: int) -> _core.ThermalSystem:
    """The solution operator of one (contact, speed) configuration for the core: eigenvectors,
    eigenvalues and the steady state per watt of heater, per kelvin of room and of object."""
    x = net.system(phi_bin, speed_bin)
    return _core.ThermalSystem(x.u, x.mu, x.ss_heater, x.ss_ambient, x.ss_object)


def _child(seq: np.random.SeedSequence, n: int) -> np.random.SeedSequence:
    return np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, n))


def _pair(v: Any) -> tuple[float, float]:
    return (float(v[0]), float(v[1]))
