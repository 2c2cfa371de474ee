"""The compiled per-sample loops (Rust crate ``aptkt-sim``) against their numpy formulation
(``numpy_reference``): the same numbers to a tight tolerance on real trial configurations, and
whole trials that do not depend on the process that simulates them."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aptkt._core import HeatKernel, LeanQueue, TextureField, sim_texture
from aptkt.sim.kinematics import Trajectory
from aptkt.sim.physics import ContactPhysics, ObjectPose
from aptkt.sim.seeding import stable_words, trial_seed_sequence
from aptkt.sim.texture import texture_acceleration
from aptkt.sim.thermal import speed_bins
from aptkt.sim.trial import TrialConditions
from aptkt.sim.world import OBJECT_SPOT
from aptkt.skin.protocol import RAW_RANGES, SCALE, to_physical

from . import numpy_reference as ref

OBJECTS = ["rough_sponge", "metal_toolbox", "ceramic_tile", "towel"]


def physics(world, name: str, trial: int = 0) -> ContactPhysics:
    obj = world.objects[name]
    seq = trial_seed_sequence(world.seed, name, "ref", trial)
    cond = TrialConditions.draw(obj, world.variation, seq, world.geometry.n_cells)
    noise = np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, *stable_words("noise")))
    pose = ObjectPose(OBJECT_SPOT, obj.height, 0.0)
    return ContactPhysics(obj, pose, cond, world.geometry, world.imperfections, noise)


def press_and_slide(ph: ContactPhysics, depth: float) -> Trajectory:
    """Down into the face, hold, slide along x and back up: contact, relaxation, waviness."""
    x, y = OBJECT_SPOT
    z = ph.shape.surface_z
    tr = Trajectory.resting(0, np.array([x - 0.02, y, z + 0.002]))
    v = (0.002 + depth) / 0.4
    tr.append(100_000_000, [x - 0.02, y, z + 0.002], [0, 0, -v], [0, 0, 0])
    tr.append(500_000_000, [x - 0.02, y, z - depth], [0, 0, 0], [0, 0, 0])
    tr.append(1_500_000_000, [x - 0.02, y, z - depth], [0.01, 0.0, 0.0], [0.5, 0.0, 0.0])
    tr.append(1_600_000_000, [x - 0.0165, y, z - depth], [0.06, 0.0, 0.0], [0, 0, 0])
    tr.append(2_200_000_000, [x + 0.0195, y, z - depth], [0.0, 0.0, 0.01], [0, 0, 0])
    return tr


@pytest.mark.parametrize("name", OBJECTS)
@pytest.mark.parametrize("depth", [0.0005, 0.002])
def test_mechanics_matches_numpy(world, name, depth):
    ph = physics(world, name)
    tr = press_and_slide(ph, depth)
    start = ph.initial_state(0, tr.p0[0])
    a, b = start.copy(), ref.RefState.of(start)
    peak = 0.0
    for t_end in [20_000_000, 400_000_000, 408_000_000, 1_000_000_000, 2_600_000_000]:
        got = ph.mechanics(a, tr, t_end)
        want = ref.mechanics(ph, b, tr, t_end)
        np.testing.assert_array_equal(got.cells, want.cells)
        np.testing.assert_array_equal(got.ks, want.ks)
        np.testing.assert_array_equal(got.t_ns, want.t_ns)
        np.testing.assert_allclose(got.pos, want.pos, rtol=0, atol=1e-15)
        scale = max(float(np.abs(want.sigma).max()), 1.0)
        peak = max(peak, float(want.sigma.max()))
        np.testing.assert_allclose(got.sigma, want.sigma, rtol=1e-9, atol=1e-9 * scale)
    assert peak > 100.0  # Pa: the trajectory does press into the object
    if ph.relaxation.weights:
        assert float(np.abs(b.relax_h).max()) > 0
    np.testing.assert_allclose(a.relax_h, b.relax_h, rtol=1e-9, atol=1e-9 * scale)
    np.testing.assert_allclose(a.latest_force, b.latest_force, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(a.next_k, b.next_k)
    assert a.t_ns == b.t_ns


def compiled_heat(ph: ContactPhysics, st, cells, t_s, phi_bin, v_bin) -> np.ndarray:
    """``aptkt_sim::thermal::heat`` through its binding, with the configurations' systems."""
    keys = sorted(set(zip(phi_bin.tolist(), v_bin.tolist())))
    index = {key: i for i, key in enumerate(keys)}
    systems = [ph.thermal.net.system(p, v) for p, v in keys]
    kernel = HeatKernel(
        np.stack([x.u for x in systems]),
        np.stack([x.mu for x in systems]),
        np.stack([ph.thermal._t_ss_cached(p, v, x) for (p, v), x in zip(keys, systems)]),
        systems[0].sqrt_c,
    )
    return kernel.heat(
        cells,
        t_s,
        np.array([index[key] for key in zip(phi_bin.tolist(), v_bin.tolist())], dtype=np.int64),
        st.thermal,
        st.thermal_t,
    )


@pytest.mark.parametrize("name", OBJECTS)
def test_heat_matches_numpy(world, name):
    ph = physics(world, name)
    tr = press_and_slide(ph, 0.002)
    st0 = ph.initial_state(0, tr.p0[0])
    chunk = ph.mechanics(st0, tr, 2_600_000_000)
    pressure = chunk.sigma.mean(axis=1)
    phi = ph.thermal.contact_bins(pressure / (pressure + ph.k.contact_pressure_half))
    speed = np.hypot(chunk.vel[:, 0], chunk.vel[:, 1])
    v_bin = np.where(pressure > 0, speed_bins(speed), 0)
    assert len(np.unique(phi)) > 3 and len(np.unique(v_bin)) > 3
    a, b = ref.RefState.of(st0), ref.RefState.of(st0)
    got = compiled_heat(ph, a, chunk.cells, chunk.t_s, phi, v_bin)
    want = ref.heat(ph, b, chunk.cells, chunk.t_s, phi, v_bin)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.thermal, b.thermal, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(a.thermal_t, b.thermal_t)
    assert float(np.ptp(got[:, 0])) > 0.01  # the contact did move the temperatures


def test_noise_matches_the_numpy_counter_stream(world):
    ph = physics(world, "towel")
    rng = np.random.default_rng(3)
    ks = rng.integers(0, 200_000, 500)
    cells = rng.integers(0, ph.n, 500)
    t_ns = rng.integers(0, 10**12, 500)
    z, arrival = ph._noise_and_arrival(ks, cells, t_ns)
    z_ref, arrival_ref = ref.noise_and_arrival(ph, ks, cells, t_ns)
    np.testing.assert_allclose(z, z_ref, rtol=1e-13, atol=1e-13)
    np.testing.assert_array_equal(arrival, arrival_ref)


@settings(max_examples=25, deadline=None)
@given(
    speed=st.floats(1e-4, 0.1),
    angle=st.floats(0, 2 * np.pi),
    pressure=st.floats(0, 5e4),
    x=st.floats(-0.05, 0.05),
)
def test_texture_matches_numpy(world, speed, angle, pressure, x):
    ph = physics(world, "rough_sponge")
    u = np.array([[x, 0.3 * x], [0.01, -0.02]])
    w = speed * np.array([[np.cos(angle), np.sin(angle)], [0.0, 1.0]])
    p = np.array([pressure, 0.5 * pressure])
    field = TextureField(
        ph.texture.kvec.tolist(), ph.texture.amplitude.tolist(), ph.texture.phase.tolist()
    )
    got = sim_texture(field, ph.texture_response, u, w, p)
    want = texture_acceleration(ph.texture, ph.k, u, w, p, ph.top_modulus, ph.mu_k)
    scale = max(float(np.abs(want).max()), 1e-12)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-10 * scale)


@pytest.mark.parametrize("name", ["rubber_mat", "rough_sponge", "wooden_board"])
def test_stick_slip_matches_numpy(world, name):
    ph = physics(world, name)
    rng = np.random.default_rng(5)
    n = 3000
    t = 0.25 + np.arange(n) / 250.0
    # Slow and fast sliding, pauses, varying load: sticking, slipping and steady stretches.
    speed = np.repeat(rng.choice([0.0, 0.002, 0.01, 0.05], 30), n // 30) * rng.uniform(0.9, 1.1, n)
    force = np.clip(0.03 + 0.01 * rng.standard_normal(n), 0.0, None)
    path = speed / 250.0
    a, b = ph.slip.rest(), ph.slip.rest()
    events = 0
    for cell in range(ph.n):
        for lo, hi in [(0, 1000), (1000, 1001), (1001, n)]:  # state carried between stretches
            s = slice(lo, hi)
            got = ph.slip.run(a, cell, t[s], path[s], force[s], speed[s])
            want = ref.slip_run(ph.slip, b, cell, t[s], path[s], force[s], speed[s])
            np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
        events += int(b.events[cell])
        assert a.events[cell] == b.events[cell] and a.ringing[cell] == b.ringing[cell]
    np.testing.assert_array_equal(a.load, b.load)
    np.testing.assert_array_equal(a.threshold, b.threshold)
    assert events > 20  # the stretches did slip


def slow_slide(ph: ContactPhysics) -> Trajectory:
    """Pressed 1 mm, then a slow slide (2 mm/s: sticking and slipping on grippy surfaces) and a
    lift."""
    x, y = OBJECT_SPOT
    z = ph.shape.surface_z
    tr = Trajectory.resting(0, np.array([x - 0.01, y, z + 0.002]))
    tr.append(100_000_000, [x - 0.01, y, z + 0.002], [0, 0, -0.0075], [0, 0, 0])
    tr.append(500_000_000, [x - 0.01, y, z - 0.001], [0, 0, 0], [0, 0, 0])
    tr.append(800_000_000, [x - 0.01, y, z - 0.001], [0.002, 0.0, 0.0], [0, 0, 0])
    tr.append(3_800_000_000, [x - 0.004, y, z - 0.001], [0.0, 0.0, 0.01], [0, 0, 0])
    return tr


@pytest.mark.parametrize(
    "name, slow",
    [
        ("rough_sponge", False),
        ("metal_toolbox", False),
        ("rubber_mat", True),
        ("ceramic_tile", True),
    ],
)
@pytest.mark.parametrize("detail", [True, False])
def test_finish_matches_numpy(world, name, slow, detail):
    """The core's whole second half of a step (heat, stick-slip, texture, arm vibration, noise,
    readings, arrival order) against the numpy formulation, over a trial's motion cut into
    steps, the state carried from step to step on both sides."""
    ph = physics(world, name)
    tr = slow_slide(ph) if slow else press_and_slide(ph, 0.002)
    start = ph.initial_state(0, tr.p0[0])
    a, b = start.copy(), ref.RefState.of(start)
    steps = [20_000_000, 400_000_000, 408_000_000, 1_000_000_000, 1_700_000_000, 4_000_000_000]
    slips = moving = 0
    for t_end in steps:
        chunk = ph.mechanics(a, tr, t_end)
        b.t_ns, b.next_k, b.relax_h = a.t_ns, a.next_k.copy(), a.relax_h.copy()
        b.relax_last, b.latest_force = a.relax_last.copy(), a.latest_force.copy()
        got, got_trace = ph.finish(a, chunk, detail=detail)
        want, want_trace = ref.finish(ph, b, chunk, detail=detail)
        for key in ("cell_index", "cell_id", "t_sample_ns", "t_ns"):
            np.testing.assert_array_equal(getattr(got, key), want[key], err_msg=key)
        for key in ("proximity", "acc", "temp", "force", "force_true"):
            np.testing.assert_allclose(
                getattr(got, key), want[key], rtol=1e-12, atol=1e-12, err_msg=key
            )
        for g, w in zip((got_trace.cell_index, got_trace.t_sample_ns), want_trace[:2]):
            np.testing.assert_array_equal(g, w)
        np.testing.assert_allclose(got_trace.force, want_trace[2], rtol=1e-13, atol=0)
        np.testing.assert_allclose(a.thermal, b.thermal, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(a.thermal_t, b.thermal_t)
        np.testing.assert_array_equal(a.last_xy, b.last_xy)
        np.testing.assert_allclose(a.slip_load, b.slip.load, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(a.slip_threshold, b.slip.threshold)
        np.testing.assert_array_equal(a.slip_events, b.slip.events)
        assert a.slip_ringing == b.slip.ringing
        slips = int(a.slip_events.sum())
        moving += int(np.any(np.abs(chunk.vel[:, :2]) > 0))
    assert moving >= 2  # the steps did slide
    if slow and name == "rubber_mat":
        assert slips > 0  # and the slow slide on rubber did stick and slip


def test_the_lean_queue_reads_what_the_skin_reads():
    """The force loop's reading from the packets in flight (``aptkt_sim::control::LeanQueue``)
    against the skin source's arithmetic in numpy: each packet's force fields quantised to the
    wire's grid and calibrated, the newest packet of each cell by arrival, summed as numpy
    sums."""
    ((scale, _),) = SCALE["force"]
    (lo_hi,) = RAW_RANGES["force"]
    rng = np.random.default_rng(7)
    n = 7
    gain, offset = rng.uniform(0.5, 2.0, (n, 3)), rng.uniform(0.0, 0.2, (n, 3))
    latest = rng.uniform(0.0, 0.3, (n, 3))
    queue = LeanQueue(gain, offset, latest)
    q_t, q_c, q_f = np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))
    for step in range(60):
        m = int(rng.integers(0, 25))
        t = rng.integers(0, 3, m).astype(np.int64) * 400_000 + step * 1_000_000
        cells = rng.integers(0, n, m).astype(np.int64)
        force = rng.uniform(-0.1, 4.5, (m, 3))  # beyond the field's range at both ends
        queue.push(t, cells, force)
        raw = np.clip(np.rint(force / scale), *lo_hi).astype(np.int64)
        newtons = gain[cells] * (to_physical("force", raw) - offset[cells])
        order = np.argsort(np.concatenate([q_t, t]), kind="stable")
        q_t = np.concatenate([q_t, t])[order]
        q_c = np.concatenate([q_c, cells])[order]
        q_f = np.concatenate([q_f, newtons])[order]
        now = step * 1_000_000 + 500_000
        queue.deliver(now)
        due = int(np.searchsorted(q_t, now, side="right"))
        latest[q_c[:due]] = q_f[:due]
        q_t, q_c, q_f = q_t[due:], q_c[due:], q_f[due:]
        assert len(queue) == q_t.size
        np.testing.assert_array_equal(queue.latest, latest)
        assert queue.reading() == float(latest.sum())
