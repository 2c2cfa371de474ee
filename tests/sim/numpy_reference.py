"""The numpy formulation of the simulator's per-sample loops, kept as the reference the compiled
core (``aptkt_sim``) is tested against: the contact mechanics with relaxation (as
``ContactPhysics.mechanics`` computed it before the loop moved to Rust), the heat exchange
run by run through :meth:`CellThermal.propagate_many`, the sensor noise, stick-slip, and the
whole second half of a step (``ContactPhysics.finish`` as it was in numpy, built on them and on
``texture_acceleration`` and ``SurfaceShape``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aptkt.sim.kinematics import Trajectory
from aptkt.sim.physics import GRAVITY, ContactPhysics, PhysicsState, _runs
from aptkt.sim.recurrence import linear_recurrence_rows
from aptkt.sim.texture import StickSlipState, texture_acceleration
from aptkt.sim.thermal import speed_bins


@dataclass
class RefState:
    """The core's ``PhysicsState`` as numpy arrays the reference updates in place."""

    t_ns: int
    next_k: np.ndarray
    relax_h: np.ndarray
    relax_last: np.ndarray
    thermal: np.ndarray
    thermal_t: np.ndarray
    last_xy: np.ndarray
    latest_force: np.ndarray
    slip: StickSlipState

    @classmethod
    def of(cls, st: PhysicsState) -> RefState:
        return cls(
            st.t_ns,
            st.next_k,
            st.relax_h,
            st.relax_last,
            st.thermal,
            st.thermal_t,
            st.last_xy,
            st.latest_force,
            StickSlipState(st.slip_load, st.slip_threshold, st.slip_events, st.slip_ringing),
        )


@dataclass
class RefChunk:
    """The samples of a stretch of time as the reference's mechanics produces them."""

    cells: np.ndarray
    ks: np.ndarray
    t_s: np.ndarray
    t_ns: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    sigma: np.ndarray

    @classmethod
    def empty(cls) -> RefChunk:
        z = np.zeros
        i = np.int64
        return cls(z(0, i), z(0, i), z(0), z(0, i), z((0, 3)), z((0, 3)), z((0, 3)), z((0, 3)))


def samples(ph: ContactPhysics, state: RefState, t_end_ns: int):
    """Cell index and sample index of every sample in ``(state.t, t_end]``, cell-major."""
    rate, phase = ph.imp.clock_rate, ph.imp.clock_phase
    last = np.floor((t_end_ns * 1e-9 - phase) * rate).astype(np.int64)
    t_last = np.rint((phase + last / rate) * 1e9).astype(np.int64)
    last = np.where(t_last > t_end_ns, last - 1, last)
    counts = np.maximum(last - state.next_k + 1, 0)
    cells = np.repeat(np.arange(ph.n), counts)
    starts = np.repeat(state.next_k, counts)
    offsets = np.arange(cells.size) - np.repeat(np.cumsum(counts) - counts, counts)
    return cells, starts + offsets


def mechanics(ph: ContactPhysics, st: RefState, traj: Trajectory, t_end_ns: int) -> RefChunk:
    st.t_ns = max(int(t_end_ns), st.t_ns)
    cells, ks = samples(ph, st, st.t_ns)
    if cells.size == 0:
        return RefChunk.empty()
    imp = ph.imp
    t_s = imp.clock_phase[cells] + ks / imp.clock_rate[cells]
    t_ns = np.rint(t_s * 1e9).astype(np.int64)
    pos, vel, acc = traj.evaluate(t_ns)
    first, last, present = _runs(cells)
    st.next_k[present] = ks[last] + 1
    sxy = pos[:, None, :2] + ph._sensor_xy[cells]
    depth = ph.shape.height(sxy) - (pos[:, 2:3] + imp.sensor_height[cells])
    elastic = ph.law.stress(np.where(np.isfinite(depth), depth, -1.0))
    sigma = np.maximum(relax(ph, st, elastic, cells, first, last, present), 0.0)
    st.latest_force[present] = (sigma * ph.k.sensor_area)[last].sum(axis=1)
    return RefChunk(cells, ks, t_s, t_ns, pos, vel, acc, sigma)


def relax(ph, st, elastic, cells, first, last, present):
    rel = ph.relaxation
    if not rel.weights:
        st.relax_last[present] = elastic[last]
        return elastic
    prev = np.empty_like(elastic)
    prev[1:] = elastic[:-1]
    prev[first] = st.relax_last[present]
    increments = elastic - prev
    lengths = last - first + 1
    width = int(lengths.max())
    pos = np.arange(cells.size) - np.repeat(first, lengths)
    row = np.repeat(np.arange(present.size), lengths)
    grid = np.zeros((present.size, width, 3))
    grid[row, pos] = increments
    dt = 1.0 / ph.imp.clock_rate[present]
    out = rel.long_term * elastic
    for i, (wgt, tau) in enumerate(zip(rel.weights, rel.times)):
        a = np.exp(-dt / tau)
        gain = (wgt * (tau / dt) * (1.0 - a))[:, None, None]
        h = linear_recurrence_rows(a, gain * grid, st.relax_h[i, present])
        out += h[row, pos]
        st.relax_h[i, present] = h[np.arange(present.size), lengths - 1]
    st.relax_last[present] = elastic[last]
    return out


def heat(ph: ContactPhysics, st: RefState, cells, t_s, phi_bin, v_bin) -> np.ndarray:
    """[LM71, PCB] temperatures, cell by cell and run by run (one exact LTI solution per run)."""
    temps = np.empty((t_s.shape[0], 2))
    first, last, present = _runs(cells)
    for c, a0, b0 in zip(present, first, last + 1):
        change = np.flatnonzero((np.diff(phi_bin[a0:b0]) != 0) | (np.diff(v_bin[a0:b0]) != 0))
        bounds = [a0, *(change + 1 + a0).tolist(), b0]
        for a, b in zip(bounds[:-1], bounds[1:]):
            dt = (t_s[a:b] - st.thermal_t[c])[None, :]
            out, end = ph.thermal.propagate_many(
                st.thermal[c : c + 1],
                dt,
                np.array([b - a - 1]),
                phi_bin[a : a + 1],
                v_bin[a : a + 1],
            )
            temps[a:b] = out[0]
            st.thermal[c] = end[0]
            st.thermal_t[c] = t_s[b - 1]
    return temps


def noise_and_arrival(ph: ContactPhysics, ks, cells, t_ns):
    """Normal deviates (n, 10) and arrival times from the numpy counter stream."""
    index = ks * ph.n + cells
    lo = int(index.min())
    u01 = ph._noise.uniform(lo, int(index.max()) - lo + 1)[index - lo]
    r = np.sqrt(-2.0 * np.log(1.0 - u01[:, 0:10:2]))
    noise = np.empty((index.size, 10))
    noise[:, 0::2] = r * np.cos(2 * np.pi * u01[:, 1:10:2])
    noise[:, 1::2] = r * np.sin(2 * np.pi * u01[:, 1:10:2])
    jitter = np.rint(u01[:, 10] * ph.k.link_jitter * 1e6).astype(np.int64)
    return noise, t_ns + ph._latency_ns + 1000 * jitter


def slip_run(ss, state, cell, t, path, force, speed):
    """``StickSlip.run`` in numpy (the reference of ``aptkt_sim::slip``)."""
    k = ss.k
    cache: dict = {}

    def z(event):
        block, off = divmod(event, 256)
        if block not in cache:
            cache[block] = ss._streams[cell].normal(block * 256, 128).reshape(-1)
        return float(cache[block][off])

    def threshold(event, f):
        return ss.mu_s * f * max(0.5, 1.0 + k.slip_threshold_sd * z(event))

    k = ss.k
    n = t.shape[0]
    dmu = ss.mu_s - ss.mu_k
    v_c = np.where(
        force > 0, dmu * force / math.sqrt(k.tangential_stiffness * k.tangential_mass), 0.0
    )
    strength = np.where((v_c > 0) & (speed < v_c), 1.0 - speed / np.maximum(v_c, 1e-300), 0.0)
    active = (strength > 0) & (path > 0)
    ring = state.ringing[cell]
    t_before = t[0] - 1.0 / k.rate_hz
    i = 0
    while i < n:
        j = i
        while j < n and active[j] == active[i]:
            j += 1
        if not active[i]:
            # Steady sliding (or none): the spring carries the kinetic friction.
            state.load[cell] = (
                ss.mu_k * force[j - 1] if (force[j - 1] > 0 and path[j - 1] > 0) else 0.0
            )
            state.threshold[cell] = np.inf
        else:
            if not np.isfinite(state.threshold[cell]):
                state.threshold[cell] = threshold(int(state.events[cell]), float(force[i]))
            load = state.load[cell] + k.tangential_stiffness * np.cumsum(path[i:j])
            while True:
                hit = int(np.searchsorted(load, state.threshold[cell], side="left"))
                if hit >= load.size:
                    break
                s = i + hit
                before = load[hit - 1] if hit > 0 else state.load[cell]
                t0 = t[s - 1] if s > 0 else t_before
                frac = (state.threshold[cell] - before) / max(load[hit] - before, 1e-15)
                drop = 2.0 * dmu * float(force[s])
                ring.append(
                    (
                        t0 + min(max(frac, 0.0), 1.0) * (t[s] - t0),
                        strength[s] * k.slip_coupling * drop / k.tangential_mass,
                    )
                )
                load[hit:] -= drop
                state.events[cell] += 1
                state.threshold[cell] = threshold(int(state.events[cell]), float(force[s]))
            state.load[cell] = float(load[-1])
        i = j
    out = np.zeros(n)
    if ring:
        ev = np.array(ring)  # (E, 2): time, peak
        tau = t[:, None] - ev[None, :, 0]
        live = tau >= 0
        wave = (
            ev[None, :, 1]
            * ss._gain
            * np.exp(-ss._decay * np.where(live, tau, 0.0))
            * np.sin(ss._omega * tau + ss._lag)
        )
        out = np.sum(np.where(live, wave, 0.0), axis=1)
        # Forget slips that have rung out (< 0.1 % of their peak).
        state.ringing[cell] = [e for e in ring if (t[-1] - e[0]) * ss._decay <= 7.0]
    return out


def finish(ph: ContactPhysics, st: RefState, chunk, *, detail: bool = True):
    """``ContactPhysics.finish`` in numpy (the reference of ``aptkt_sim::readout``): heat,
    stick-slip, texture, the arm's vibration, noise and readings of the samples of ``chunk``;
    updates ``st`` in place. Returns the frames' fields (a dict, arrival order) and the force
    trace (cells, t_ns, force)."""
    k, imp = ph.k, ph.imp
    cells, ks, t_s, t_ns = chunk.cells, chunk.ks, chunk.t_s, chunk.t_ns
    pos, vel, acc, sigma = chunk.pos, chunk.vel, chunk.acc, chunk.sigma
    first, last, present = _runs(cells)
    f_true = sigma * k.sensor_area
    f_cell = f_true.sum(axis=1)
    pressure = sigma.mean(axis=1)

    speed = np.hypot(vel[:, 0], vel[:, 1])
    in_contact = pressure > 0
    phi_bin = ph.thermal.contact_bins(pressure / (pressure + k.contact_pressure_half))
    v_bin = np.where(in_contact, speed_bins(speed), 0)
    temps = heat(ph, st, cells, t_s, phi_bin, v_bin)

    centre = pos[:, :2] + ph._centres[cells]
    prev = np.empty_like(centre)
    prev[1:] = centre[:-1]
    prev[first] = st.last_xy[present]
    path = np.where(in_contact, np.hypot(*(centre - prev).T), 0.0)
    st.last_xy[present] = centre[last]
    slip = np.zeros(cells.size)
    ss = ph.slip
    v_c = (ss.mu_s - ss.mu_k) * f_cell / math.sqrt(k.tangential_stiffness * k.tangential_mass)
    if any(st.slip.ringing) or np.any((speed < v_c) & (path > 0) & (f_cell > 0)):
        for c, a0, b0 in zip(present, first, last + 1):
            s = slice(a0, b0)
            slip[s] = slip_run(ss, st.slip, int(c), t_s[s], path[s], f_cell[s], speed[s])
    else:  # no slip possible: the springs carry the kinetic friction (or nothing)
        f, p = f_cell[last], path[last]
        st.slip.load[present] = np.where((f > 0) & (p > 0), ss.mu_k * f, 0.0)
        st.slip.threshold[present] = np.inf

    rows = np.arange(cells.size) if detail else last
    c_e = cells[rows]
    u = ph.shape.to_object(centre[rows])
    w = ph.shape.to_object_direction(vel[rows, :2])
    tex = texture_acceleration(ph.texture, k, u, w, pressure[rows], ph.top_modulus, ph.mu_k)
    tex[:, 0] += slip[rows]
    tex[:, 2] += 0.3 * slip[rows]
    sp = speed[rows]
    direction = np.where(
        sp[:, None] > 1e-9, vel[rows, :2] / np.maximum(sp, 1e-12)[:, None], [1.0, 0.0]
    )
    world = acc[rows] + arm_vibration(ph, t_s[rows], vel[rows])
    world[:, :2] += tex[:, 0:1] * direction + tex[:, 1:2] * np.stack(
        [-direction[:, 1], direction[:, 0]], axis=1
    )
    world[:, 2] += tex[:, 2] + GRAVITY
    acc_cell = np.einsum("mi,mij->mj", world, ph._axes[c_e]) / GRAVITY

    noise, arrival = noise_and_arrival(ph, ks[rows], c_e, t_ns[rows])
    gain = imp.force_gain[c_e] / ph._gain_drift[c_e][:, None]
    force = imp.force_offset[c_e] + (f_true[rows] + k.force_noise * noise[:, 0:3]) / gain
    acc_g = acc_cell + imp.acc_bias[c_e] + k.acc_noise * noise[:, 3:6]
    temp = np.stack(
        [
            temps[rows, 1] + k.die_self_heating + k.die_temp_noise * noise[:, 6],
            temps[rows, 0] + k.temp_noise * noise[:, 7],
        ],
        axis=1,
    )
    below = ph.shape.height(centre[rows])
    on_face = np.isfinite(below)
    gap = np.maximum(pos[rows, 2] - np.where(on_face, below, 0.0), 0.0)
    refl = np.where(on_face, ph.obj.reflectivity, k.table_reflectivity)
    prox = (
        k.prox_dark
        + k.prox_gain * refl / (1.0 + (gap / k.prox_distance) ** 2)
        + k.prox_noise * noise[:, 8]
    )
    frames = {
        "cell_index": c_e,
        "cell_id": ph.cell_ids[c_e],
        "t_sample_ns": t_ns[rows],
        "t_ns": arrival,
        "proximity": prox,
        "acc": acc_g,
        "temp": temp,
        "force": force,
        "force_true": f_cell[rows],
    }
    order = np.lexsort((c_e, arrival))
    return {key: v[order] for key, v in frames.items()}, (cells, t_ns, f_cell)


def arm_vibration(ph: ContactPhysics, t_s: np.ndarray, vel: np.ndarray) -> np.ndarray:
    """The arm's own vibration while it moves (m/s^2, base frame)."""
    cond = ph.cond
    speed = np.linalg.norm(vel, axis=1)
    if not np.any(speed > 1e-6) or cond.arm_vibration <= 0:
        return np.zeros((t_s.size, 3))
    modes = np.asarray(cond.arm_modes)  # (m, 5): Hz, phase, dx, dy, dz
    amp = cond.arm_vibration * GRAVITY * np.sqrt(2.0 / len(modes)) * np.minimum(speed / 0.05, 2.0)
    wave = np.sin(2 * np.pi * modes[:, 0][None, :] * t_s[:, None] + modes[:, 1][None, :])
    return amp[:, None] * (wave @ modes[:, 2:5])
