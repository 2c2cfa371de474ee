"""The numpy formulation of the simulator's per-sample loops, kept as the reference the compiled
core (``aptkt_sim``) is tested against: the contact mechanics with relaxation (as
``ContactPhysics.mechanics`` computed it before the loop moved to Rust) and the heat exchange
run by run through :meth:`CellThermal.propagate_many`."""

from __future__ import annotations

import math

import numpy as np

from aptkt.sim.kinematics import Trajectory
from aptkt.sim.physics import ContactPhysics, MechChunk, PhysicsState, _runs
from aptkt.sim.recurrence import linear_recurrence_rows


def samples(ph: ContactPhysics, state: PhysicsState, t_end_ns: int):
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


def mechanics(ph: ContactPhysics, st: PhysicsState, traj: Trajectory, t_end_ns: int) -> MechChunk:
    st.t_ns = max(int(t_end_ns), st.t_ns)
    cells, ks = samples(ph, st, st.t_ns)
    if cells.size == 0:
        return MechChunk.empty()
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
    return MechChunk(cells, ks, t_s, t_ns, pos, vel, acc, sigma)


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


def heat(ph: ContactPhysics, st: PhysicsState, cells, t_s, phi_bin, v_bin) -> np.ndarray:
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
