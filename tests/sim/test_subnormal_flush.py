"""The thermal networks' eigen-decompositions run with subnormals flushed to zero (LAPACK meets
subnormal intermediates on stiff chains and slows down ~100x): the same results, bit for bit,
and the floating-point unit restored afterwards."""

from __future__ import annotations

import numpy as np

from aptkt._core import _flush_subnormals
from aptkt.sim.thermal import CONTACT_STEPS, SPEED_STEP, thermal_network


def test_flushing_subnormals_does_not_change_the_decompositions(world):
    for name in ("metal_toolbox", "hard_box", "biscuit_box", "rough_sponge"):
        obj = world.objects[name]
        net = thermal_network(
            world.geometry.constants, tuple(obj.layers), float(obj.surface.contact_conductance)
        )
        for phi, v in [(0, 0), (7, 0), (20, 0), (12, 5), (20, 30)]:
            k, *_ = net._build(phi / CONTACT_STEPS, v * SPEED_STEP)
            s = 1.0 / np.sqrt(net.cap)
            m = k * s[:, None] * s[None, :]
            plain = np.linalg.eigh(m)
            previous = _flush_subnormals(True)
            try:
                flushed = np.linalg.eigh(m)
            finally:
                _flush_subnormals(False, previous)
            np.testing.assert_array_equal(flushed[0], plain[0])
            np.testing.assert_array_equal(flushed[1], plain[1])


def test_the_floating_point_unit_is_restored():
    before = _flush_subnormals(False)
    _flush_subnormals(False, before)
    tiny = np.float64(1e-310)
    assert tiny * 0.5 > 0  # subnormals live
    previous = _flush_subnormals(True)
    try:
        if previous or _flush_subnormals(True):  # x86-64: the flags are set now
            assert tiny * np.float64(0.5) == 0
    finally:
        _flush_subnormals(False, previous)
    status = 0x3F  # the exception flags, which operations set as they go
    assert _flush_subnormals(False, previous) & ~status == before & ~status
    assert tiny * 0.5 > 0
