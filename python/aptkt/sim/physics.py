"""The contact physics of one trial: from the TCP's motion to every sensor value of every cell.

:class:`ContactPhysics` is a pure step function, ``step(state, trajectory, t_end) -> (state',
frames)``: it produces each cell's samples whose sample time falls in ``(state.t, t_end]``.
Because every stateful part is integrated exactly at the sample times and all randomness is
addressed by (cell, sample index), the output does not depend on how a motion is cut into
steps, and a step can be undone by keeping the old state (the simulated robot uses that to
stop exactly where a safety limit is crossed).

Units: SI inside; frames carry the protocol's physical units (g, °C, normalised force).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aptkt.sim.kinematics import Trajectory
from aptkt.sim.mechanics import IndentationLaw, RelaxationState, SurfaceShape, relax
from aptkt.sim.objects import ObjectSpec, Relaxation
from aptkt.sim.patch import PatchGeometry, PatchImperfections, SkinConstants
from aptkt.sim.seeding import CounterStream
from aptkt.sim.texture import StickSlip, StickSlipState, texture_acceleration, texture_field, waviness_waves
from aptkt.sim.thermal import CellThermal, contact_bins
from aptkt.sim.trial import TrialConditions

__all__ = ["GRAVITY", "Frames", "ForceTrace", "PhysicsState", "ContactPhysics", "ObjectPose"]

GRAVITY = 9.80665
#: Cell accelerometer axes in the base frame for a skin facing down: x along base x, z out of
#: the skin (base -z), y completing a right-handed frame.
_FLIP = np.diag([1.0, -1.0, -1.0])
_NOISE_SLOTS = 10  # normals per sample: force 3, acc 3, temp 2, proximity 1, spare 1


@dataclass(frozen=True)
class ObjectPose:
    """Where the object's top face really is (the robot only knows the nominal placement)."""

    centre: tuple[float, float]
    surface_z: float
    rotation: float  # rad


@dataclass
class Frames:
    """Sensor samples of all cells in arrival order, in physical units."""

    cell_index: np.ndarray  # (n,) 0..6
    cell_id: np.ndarray  # (n,)
    t_sample_ns: np.ndarray  # (n,)
    t_ns: np.ndarray  # (n,) arrival time on the PC
    proximity: np.ndarray  # (n,)
    acc: np.ndarray  # (n, 3) g
    temp: np.ndarray  # (n, 2) °C: accelerometer die, LM71
    force: np.ndarray  # (n, 3) normalised reading (offset + F / gain)
    force_true: np.ndarray  # (n,) N, true normal force on the cell (what a wrench sensor sees)

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    @classmethod
    def empty(cls) -> Frames:
        z = np.zeros
        return cls(z(0, np.int64), z(0, np.int64), z(0, np.int64), z(0, np.int64), z(0), z((0, 3)),
                   z((0, 2)), z((0, 3)), z(0))

    def take(self, index: np.ndarray | slice) -> Frames:
        return Frames(**{k: getattr(self, k)[index] for k in self.__dataclass_fields__})

    def last_per_cell(self) -> Frames:
        """Only the newest sample of each cell (used to skip unobserved stretches)."""
        keep = []
        for c in np.unique(self.cell_index):
            keep.append(np.flatnonzero(self.cell_index == c)[-1])
        return self.take(np.sort(np.array(keep, dtype=np.int64)))


@dataclass
class ForceTrace:
    """True normal force of every sample (also those not turned into frames), sample order per
    cell: what the robot's own wrench sensing sees."""

    cell_index: np.ndarray  # (m,)
    t_sample_ns: np.ndarray  # (m,)
    force: np.ndarray  # (m,) N on the cell

    @classmethod
    def concat(cls, parts: list[ForceTrace]) -> ForceTrace:
        if not parts:
            return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("cell_index", "t_sample_ns", "force")))

    def total_at(self, ticks_ns: np.ndarray, latest: np.ndarray) -> np.ndarray:
        """Total force at each tick: every cell's newest sample at or before the tick (``latest``
        holds each cell's force before this trace)."""
        ticks_ns = np.asarray(ticks_ns, dtype=np.int64)
        total = np.zeros(ticks_ns.shape[0])
        for c in range(latest.shape[0]):
            m = self.cell_index == c
            t, f = self.t_sample_ns[m], self.force[m]
            idx = np.searchsorted(t, ticks_ns, side="right") - 1
            total += np.where(idx >= 0, f[np.maximum(idx, 0)] if f.size else 0.0, latest[c])
        return total


@dataclass
class PhysicsState:
    t_ns: int  # everything with sample time <= t_ns has been produced
    next_k: np.ndarray  # (n,) next sample index of each cell
    relax: list[RelaxationState]  # per cell, (terms, 3)
    thermal: np.ndarray  # (n, N)
    thermal_t: np.ndarray  # (n,) s, time of the thermal state (the cell's last sample)
    last_xy: np.ndarray  # (n, 2) cell centre at its last sample (for sliding distances)
    latest_force: np.ndarray  # (n,) N, true force on each cell at its last sample
    slip: StickSlipState = field(default_factory=lambda: None)  # type: ignore[assignment]

    def copy(self) -> PhysicsState:
        return PhysicsState(self.t_ns, self.next_k.copy(), [r.copy() for r in self.relax], self.thermal.copy(),
                            self.thermal_t.copy(), self.last_xy.copy(), self.latest_force.copy(), self.slip.copy())


class ContactPhysics:
    """Physics of one object in one trial against the simulated patch."""

    def __init__(self, obj: ObjectSpec, pose: ObjectPose, conditions: TrialConditions, geometry: PatchGeometry,
                 imperfections: PatchImperfections, noise_seq: np.random.SeedSequence):
        self.obj, self.cond, self.geo, self.imp = obj, conditions, geometry, imperfections
        k = self.k = geometry.constants
        self.law = IndentationLaw(obj.layers, k.skin_stiffness, conditions.modulus_scale)
        self.relaxation = Relaxation(tuple(w * conditions.relaxation_scale for w in obj.relaxation.weights),
                                     obj.relaxation.times)
        if self.relaxation.long_term <= 0.05:  # keep the long-term stiffness positive
            s = 0.95 / sum(self.relaxation.weights)
            self.relaxation = Relaxation(tuple(w * s for w in self.relaxation.weights), obj.relaxation.times)
        self.shape = SurfaceShape(
            centre=(pose.centre[0] + conditions.shift[0], pose.centre[1] + conditions.shift[1]),
            rotation=pose.rotation + conditions.rotation,
            surface_z=pose.surface_z,
            tilt=conditions.tilt,
            crown_radius=obj.crown_radius,
            waves=waviness_waves(obj),
            size=obj.size,
        )
        self.texture = texture_field(obj).scaled(conditions.roughness_scale)
        mu_s = obj.surface.friction_static * conditions.friction_scale
        mu_k = obj.surface.friction_kinetic * conditions.friction_scale
        self.mu_k = mu_k
        self.top_modulus = obj.top.modulus * conditions.modulus_scale
        self.thermal = CellThermal(k, obj.layers, obj.surface.contact_conductance * conditions.conductance_scale,
                                   conditions.ambient, conditions.object_temperature)
        self.n = n = geometry.n_cells
        self.slip = StickSlip(k, mu_s, mu_k, np.random.SeedSequence(noise_seq.entropy, spawn_key=(*noise_seq.spawn_key, 1)), n)
        self._noise = [CounterStream(np.random.SeedSequence(noise_seq.entropy, spawn_key=(*noise_seq.spawn_key, 100 + c)),
                                     _NOISE_SLOTS) for c in range(n)]
        self._jitter = [CounterStream(np.random.SeedSequence(noise_seq.entropy, spawn_key=(*noise_seq.spawn_key, 200 + c)),
                                      2) for c in range(n)]
        self._sensor_xy = geometry.sensor_positions  # (7, 3, 2)
        self._centres = geometry.cell_centres  # (n, 2)
        self._axes = np.stack([(_FLIP @ imperfections.mount_rotation[c]) for c in range(n)])  # cell axes in base
        self.cell_ids = np.asarray(geometry.cell_ids, dtype=np.int64)

    # ---------------------------------------------------------------------------------------
    def initial_state(self, t_ns: int, position: np.ndarray) -> PhysicsState:
        """At rest at ``position`` (out of contact), skin in its steady state plus the trial's offset."""
        start = self.thermal.initial_state(self.cond.skin_offset)
        t_s = t_ns * 1e-9
        # First sample index after t_ns for every cell.
        next_k = np.array([max(0, math.floor((t_s - self.imp.clock_phase[c]) * self.imp.clock_rate[c]) + 1)
                           for c in range(self.n)], dtype=np.int64)
        return PhysicsState(
            t_ns=int(t_ns),
            next_k=next_k,
            relax=[RelaxationState.rest(self.relaxation, (3,)) for _ in range(self.n)],
            thermal=np.tile(start, (self.n, 1)),
            thermal_t=np.full(self.n, t_s),
            last_xy=np.asarray(position[:2], dtype=np.float64) + self._centres,
            latest_force=np.zeros(self.n),
            slip=self.slip.rest(),
        )

    def sample_times(self, cell: int, k0: int, t_end_ns: int) -> np.ndarray:
        """Sample indices of ``cell`` from ``k0`` up to the last one at or before ``t_end_ns``."""
        rate, phase = self.imp.clock_rate[cell], self.imp.clock_phase[cell]
        k1 = math.floor((t_end_ns * 1e-9 - phase) * rate)
        if k1 < k0:
            return np.zeros(0, dtype=np.int64)
        ks = np.arange(k0, k1 + 1, dtype=np.int64)
        t_ns = np.rint((phase + ks / rate) * 1e9).astype(np.int64)
        return ks[t_ns <= t_end_ns]

    def step(self, state: PhysicsState, traj: Trajectory, t_end_ns: int, *,
             detail: bool = True) -> tuple[PhysicsState, Frames, ForceTrace]:
        """Advance to ``t_end_ns``: the new state, the frames (arrival order) and the true force of
        every sample. With ``detail=False`` only each cell's newest sample becomes a frame (the
        state is integrated exactly all the same)."""
        new = state.copy()
        new.t_ns = max(int(t_end_ns), state.t_ns)
        parts, traces = [], []
        for c in range(self.n):
            ks = self.sample_times(c, int(state.next_k[c]), new.t_ns)
            if ks.size == 0:
                continue
            frames_c, trace_c = self._cell(new, traj, c, ks, detail)
            parts.append(frames_c)
            traces.append(trace_c)
            new.next_k[c] = ks[-1] + 1
        if not parts:
            return new, Frames.empty(), ForceTrace.concat([])
        frames = Frames(**{name: np.concatenate([getattr(p, name) for p in parts]) for name in Frames.__dataclass_fields__})
        order = np.lexsort((frames.cell_index, frames.t_ns))
        return new, frames.take(order), ForceTrace.concat(traces)

    # ---------------------------------------------------------------------------------------
    def _cell(self, st: PhysicsState, traj: Trajectory, c: int, ks: np.ndarray, detail: bool) -> tuple[Frames, ForceTrace]:
        k, imp = self.k, self.imp
        rate, phase = imp.clock_rate[c], imp.clock_phase[c]
        t_s = phase + ks / rate
        t_ns = np.rint(t_s * 1e9).astype(np.int64)
        pos, vel, acc = traj.evaluate(t_ns)
        n = ks.size

        # --- indentation at the three force sensors
        sxy = pos[:, None, :2] + self._sensor_xy[c][None, :, :]  # (n, 3, 2)
        surface = self.shape.height(sxy)  # (n, 3)
        sensor_z = pos[:, 2:3] + imp.sensor_height[c][None, :]
        depth = surface - sensor_z
        elastic = self.law.stress(np.where(np.isfinite(depth), depth, -1.0))
        sigma, st.relax[c] = relax(self.relaxation, elastic, 1.0 / rate, st.relax[c])
        sigma = np.maximum(sigma, 0.0)
        f_true = sigma * k.sensor_area  # (n, 3) N
        st.latest_force[c] = float(f_true[-1].sum())
        trace = ForceTrace(np.full(n, c, dtype=np.int64), t_ns.copy(), f_true.sum(axis=1))
        pressure = sigma.mean(axis=1)  # (n,)

        # --- heat exchange, piecewise in (contact fraction, sliding speed)
        speed_xy = np.hypot(vel[:, 0], vel[:, 1])
        in_contact = pressure > 0
        phi_bin = contact_bins(pressure / (pressure + k.contact_pressure_half))
        slide = np.where(in_contact & (speed_xy > 1e-4), np.round(speed_xy, 3), 0.0)
        temps = np.empty((n, 2))
        change = np.flatnonzero((np.diff(phi_bin) != 0) | (np.diff(slide) != 0)) + 1
        bounds = np.concatenate([[0], change, [n]])
        state_t, t_prev = st.thermal[c], st.thermal_t[c]
        for a, b in zip(bounds[:-1], bounds[1:]):
            out, state_t = self.thermal.propagate(state_t, t_s[a:b] - t_prev, int(phi_bin[a]), float(slide[a]))
            temps[a:b] = out
            t_prev = t_s[b - 1]
        st.thermal[c], st.thermal_t[c] = state_t, t_prev

        # --- vibration: texture while sliding, stick-slip, motion and gravity
        centre = pos[:, :2] + self._centres[c]
        prev = np.vstack([st.last_xy[c][None, :], centre[:-1]])
        path = np.where(in_contact, np.hypot(*(centre - prev).T), 0.0)
        st.last_xy[c] = centre[-1]
        u = self.shape.to_object(centre)
        w = self.shape.to_object_direction(vel[:, :2])
        tex = texture_acceleration(self.texture, k, u, w, pressure, self.top_modulus, self.mu_k)
        slip = self.slip.run(st.slip, c, t_s, path, f_true.sum(axis=1), speed_xy)
        tex[:, 0] += slip
        tex[:, 2] += 0.3 * slip
        direction = np.where(speed_xy[:, None] > 1e-9, vel[:, :2] / np.maximum(speed_xy, 1e-12)[:, None], [1.0, 0.0])
        world = acc.copy()
        world[:, :2] += tex[:, 0:1] * direction + tex[:, 1:2] * np.stack([-direction[:, 1], direction[:, 0]], axis=1)
        world[:, 2] += tex[:, 2] + GRAVITY  # specific force: an accelerometer at rest reads +1 g up
        acc_cell = world @ self._axes[c] / GRAVITY  # rows: base-frame vectors projected on cell axes

        if not detail:  # keep only the newest sample; the state above is already exact
            sl = slice(n - 1, n)
            ks, t_ns, f_true, temps, acc_cell, pos = ks[sl], t_ns[sl], f_true[sl], temps[sl], acc_cell[sl], pos[sl]
            n = 1

        noise = self._noise[c].normal(int(ks[0]), n)
        gain, offset = imp.force_gain[c], imp.force_offset[c]
        force = offset + (f_true + k.force_noise * noise[:, 0:3]) / gain
        acc_g = acc_cell + imp.acc_bias[c] + k.acc_noise * noise[:, 3:6]
        temp = np.stack([temps[:, 1] + k.die_self_heating + k.die_temp_noise * noise[:, 6],
                         temps[:, 0] + k.temp_noise * noise[:, 7]], axis=1)
        # --- proximity: reflection from whatever is below the cell centre
        below = self.shape.height(pos[:, :2] + self._centres[c])
        on_face = np.isfinite(below)
        gap = np.maximum(pos[:, 2] - np.where(on_face, below, 0.0), 0.0)
        refl = np.where(on_face, self.obj.reflectivity, k.table_reflectivity)
        prox = k.prox_dark + k.prox_gain * refl / (1.0 + (gap / k.prox_distance) ** 2) + k.prox_noise * noise[:, 8]
        jitter = self._jitter[c].uniform(int(ks[0]), n)[:, 0]
        arrival = t_ns + int(round(k.link_latency * 1e9)) + np.rint(jitter * k.link_jitter * 1e9).astype(np.int64)
        return Frames(
            cell_index=np.full(n, c, dtype=np.int64),
            cell_id=np.full(n, self.cell_ids[c], dtype=np.int64),
            t_sample_ns=t_ns,
            t_ns=arrival,
            proximity=prox,
            acc=acc_g,
            temp=temp,
            force=force,
            force_true=f_true.sum(axis=1),
        ), trace
