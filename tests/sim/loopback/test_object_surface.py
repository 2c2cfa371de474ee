"""The simulated world's contact physics plugged into the loopback controller."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aptkt.sim.loopback import contact as contact_models
from aptkt.sim.patch import SkinConstants

FLAT = """
schema_version = 1
[[object]]
name = "flat_foam"
index = 90
role = "new"
height = 0.02
size = [0.2, 0.2]
waviness = 0.0
reflectivity = 0.5
  [[object.layer]]
  material = "foam"
  thickness = 0.02
  modulus = 50e3
  densification_strain = 0.7
  conductivity = 0.04
  heat_capacity = 5.0e4
  [object.surface]
  friction_static = 1.0
  friction_kinetic = 0.8
  roughness_rms = 10e-6
  roughness_band = [0.4e-3, 4e-3]
  roughness_exponent = 0.6
  contact_conductance = 1500
"""


@pytest.fixture(scope="module")
def flat(tmp_path_factory):
    path = tmp_path_factory.mktemp("objects") / "flat.toml"
    path.write_text(textwrap.dedent(FLAT))
    return contact_models.build(
        {
            "type": "sim_object",
            "object": "flat_foam",
            "x": 0.0,
            "y": -0.5,
            "library_files": [str(path)],
        }
    )


def reference_pressure(depth: float, k_skin: float, h: float, e: float, eps_d: float) -> float:
    """Solve depth = s/k_skin + h s / (e + s/eps_d) for the pressure s by bisection."""
    lo, hi = 0.0, 1.0
    while hi / k_skin + h * hi / (e + hi / eps_d) < depth:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid / k_skin + h * mid / (e + mid / eps_d) < depth:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@settings(max_examples=30, deadline=None)
@given(depth=st.floats(1e-6, 0.01))
def test_flat_object_force_is_the_layer_law_on_all_21_sensors(flat, depth):
    k = SkinConstants()
    expected = 21 * k.sensor_area * reference_pressure(depth, k.skin_stiffness, 0.02, 50e3, 0.7)
    assert flat.normal_force((0.0, -0.5, 0.02 - depth, math.pi, 0.0, 0.0)) == pytest.approx(
        expected, rel=1e-3
    )


def test_no_force_above_the_face_or_beside_the_object(flat):
    assert flat.normal_force((0.0, -0.5, 0.0201, math.pi, 0.0, 0.0)) == 0.0
    assert flat.normal_force((0.5, -0.5, 0.0, math.pi, 0.0, 0.0)) == 0.0
    # Half the patch over the edge: only the sensors above the face carry load.
    edge = flat.sensor_forces((0.1, -0.5, 0.019, math.pi, 0.0, 0.0))
    on = edge > 0
    assert 0 < on.sum() < 21 and np.allclose(edge[on], edge[on].max())


@pytest.mark.parametrize("name", ["ceramic_tile", "rough_sponge", "towel", "paper_box"])
def test_library_objects_stiffen_monotonically_with_depth(name):
    model = contact_models.build({"type": "sim_object", "object": name, "x": 0.0, "y": -0.5})
    z0 = model.shape.surface_z
    forces = [
        model.normal_force((0.0, -0.5, z0 - d, math.pi, 0.0, 0.0))
        for d in np.linspace(-1e-3, 3e-3, 41)
    ]
    assert forces[0] == 0.0 and np.all(np.diff(forces) >= 0) and forces[-1] > 1.0


def test_harder_objects_push_back_harder():
    f = {}
    for name in ("rough_sponge", "ceramic_tile"):
        model = contact_models.build({"type": "sim_object", "object": name, "x": 0.0, "y": -0.5})
        f[name] = model.normal_force((0.0, -0.5, model.shape.surface_z - 0.001, math.pi, 0.0, 0.0))
    assert f["ceramic_tile"] > 2 * f["rough_sponge"]


def test_unknown_object_is_a_clear_error():
    with pytest.raises(Exception, match="glass_of_water"):
        contact_models.build({"type": "sim_object", "object": "glass_of_water", "x": 0.0, "y": 0.0})
