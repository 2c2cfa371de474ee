"""Numerical building blocks against independent references: recurrences, counter-based noise,
the layered indentation law, viscoelastic relaxation and the thermal network."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aptkt.sim.mechanics import IndentationLaw, RelaxationState, relax
from aptkt.sim.objects import Layer, Relaxation, default_library
from aptkt.sim.patch import SkinConstants
from aptkt.sim.recurrence import linear_recurrence, linear_recurrence_rows
from aptkt.sim.seeding import CounterStream, seed_sequence, stable_words
from aptkt.sim.thermal import CellThermal


def naive(a, x, y0):
    y, out = y0, []
    for v in x:
        y = a * y + v
        out.append(y)
    return np.array(out)


@settings(max_examples=60, deadline=None)
@given(a=st.floats(0.01, 1.0), n=st.integers(0, 3000), seed=st.integers(0, 2**31))
def test_linear_recurrence_matches_loop(a, n, seed):
    rng = np.random.default_rng(seed)
    x, y0 = rng.normal(size=n), rng.normal()
    got = linear_recurrence(a, x, y0)
    np.testing.assert_allclose(got, naive(a, x, y0), rtol=1e-9, atol=1e-9 * (1 + np.abs(x).sum()))


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 1500), rows=st.integers(1, 7), seed=st.integers(0, 2**31))
def test_row_recurrence_matches_loop(n, rows, seed):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.5, 1.0, rows)
    x, y0 = rng.normal(size=(rows, n, 3)), rng.normal(size=(rows, 3))
    got = linear_recurrence_rows(a, x, y0)
    for r in range(rows):
        for c in range(3):
            np.testing.assert_allclose(
                got[r, :, c], naive(a[r], x[r, :, c], y0[r, c]), rtol=1e-9, atol=1e-8
            )


def test_counter_stream_is_chunking_independent_and_normal():
    s = CounterStream(seed_sequence(3, "x"), 10)
    whole = s.normal(5, 4000)
    parts = np.concatenate([s.normal(5, 1), s.normal(6, 999), s.normal(1005, 3000)])
    assert np.array_equal(whole, parts)
    assert abs(whole.mean()) < 0.02 and abs(whole.std() - 1) < 0.02
    other = CounterStream(seed_sequence(3, "y"), 10).normal(5, 4000)
    assert abs(np.corrcoef(whole.ravel(), other.ravel())[0, 1]) < 0.02


def test_seed_keys_do_not_depend_on_the_process():
    # Python's hash() is salted per process; the keys must not be.
    code = (
        "from aptkt.sim.seeding import stable_words; print(stable_words('rough_sponge', 'P1', 3))"
    )
    outs = {
        subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            check=True,
            env={**os.environ, "PYTHONHASHSEED": str(h)},
        ).stdout
        for h in (1, 2)
    }
    assert outs == {f"{stable_words('rough_sponge', 'P1', 3)}\n"}
    assert stable_words("a", "bc") != stable_words("ab", "c")  # fields are delimited


def test_indentation_law_against_series_springs():
    # Linear layers (no lock-up) in series with the skin: k_total = 1 / (1/k_skin + Σ h/E).
    layers = [Layer("a", 0.01, 2e4, 1.0, 0.1, 1e6), Layer("b", 0.02, 1e5, 1.0, 0.1, 1e6)]
    law = IndentationLaw(layers, 1.3e6)
    k = 1.0 / (1 / 1.3e6 + 0.01 / 2e4 + 0.02 / 1e5)
    d = np.array([1e-6, 1e-5, 3e-5])  # small strains: the lock-up terms are negligible
    np.testing.assert_allclose(law.stress(d), k * d, rtol=1e-3)
    assert np.all(law.stress(np.array([-1e-3, 0.0])) == 0)
    # monotone, and inverse of depth()
    s = law.stress(np.linspace(0, 5e-3, 200))
    assert np.all(np.diff(s) > 0)
    np.testing.assert_allclose(law.depth(s[1:]), np.linspace(0, 5e-3, 200)[1:], rtol=1e-5)


def test_soft_over_hard_stiffens_faster_than_uniform_sponge():
    """Paper §1.2: pressing harder reaches the metal under the padding, not under the sponge."""
    lib, k = default_library(), SkinConstants()
    soft_over_hard = IndentationLaw(lib["padded_case"].layers, k.skin_stiffness)
    sponge = IndentationLaw(lib["rough_sponge"].layers, k.skin_stiffness)
    f = {
        name: law.stress(np.array([1e-3, 2e-3]))
        for name, law in (("soh", soft_over_hard), ("sponge", sponge))
    }
    assert f["soh"][1] - f["soh"][0] > 1.3 * (f["sponge"][1] - f["sponge"][0])
    assert f["soh"][1] / f["soh"][0] > f["sponge"][1] / f["sponge"][0]


def test_relaxation_step_response():
    # A step held constant relaxes as G(t) = g_inf + Σ w_i exp(-t/τ_i) (after the ramp sample).
    rel = Relaxation((0.2, 0.1), (0.5, 4.0))
    dt = 0.004
    n = 10000
    elastic = np.full((n, 1), 100.0)
    elastic[0] = 0.0
    out, _ = relax(rel, elastic, dt, RelaxationState.rest(rel, (1,)))
    t = (np.arange(n) - 1) * dt
    # the ramp over one sample is exact for piecewise-linear input: compare after it
    expected = 100.0 * (
        rel.long_term
        + sum(
            w * (tau / dt) * (1 - math.exp(-dt / tau)) * np.exp(-t / tau)
            for w, tau in zip(rel.weights, rel.times)
        )
    )
    np.testing.assert_allclose(out[1:, 0], expected[1:], rtol=1e-9)
    assert out[-1, 0] == pytest.approx(100.0 * rel.long_term, rel=0.01)


def test_thermal_network_energy_and_limits():
    lib, k = default_library(), SkinConstants()
    th = CellThermal(k, lib["metal_toolbox"].layers, 2000.0, ambient=24.0, object_temperature=24.0)
    start = th.initial_state()
    # In free air the initial state is a steady state: it does not drift.
    out, end = th.propagate(start, np.array([1.0, 100.0]), 0, 0)
    np.testing.assert_allclose(out[:, 0], start[0], atol=1e-9)
    # Skin warmer than the room; in contact (over an action's time) it cools towards the object.
    assert start[0] > 24.0 + 3
    out, end = th.propagate(start, np.linspace(0.01, 15, 50), 20, 0)
    assert np.all(np.diff(out[:, 0]) <= 1e-12) and 24.0 < out[-1, 0] < start[0] - 1.0
    # Chunked propagation equals one step (an exact LTI solution).
    a, mid = th.propagate(start, np.array([2.0]), 20, 0)
    b, _ = th.propagate(mid, np.array([3.0]), 20, 0)
    c, _ = th.propagate(start, np.array([5.0]), 20, 0)
    np.testing.assert_allclose(b, c, rtol=1e-12)


def test_metal_draws_heat_faster_than_foam():
    lib, k = default_library(), SkinConstants()
    t = np.linspace(0.1, 15, 150)
    drop = {}
    for name in ("metal_toolbox", "biscuit_box", "rough_sponge", "smooth_sponge", "towel"):
        o = lib[name]
        th = CellThermal(k, o.layers, o.surface.contact_conductance, 24.0, 24.0)
        s0 = th.initial_state()
        out, _ = th.propagate(s0, t, 20, 0)
        drop[name] = s0[0] - out[:, 0]
    for metal in ("metal_toolbox", "biscuit_box"):
        for soft in ("rough_sponge", "smooth_sponge", "towel"):
            assert np.all(drop[metal][10:] > 3 * drop[soft][10:])
