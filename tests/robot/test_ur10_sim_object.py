"""The UR10 backend on a simulated-world object: the loopback controller with the world's
contact physics (:class:`aptkt.sim.loopback.object_surface.SimObjectSurface`), through ur_rtde.
An attempt that failed while the watchdog's feed was kept waiting is repeated
(``tests/robot/test_ur10_exploration.py``)."""

from __future__ import annotations

import math

import pytest
import rtde_control  # noqa: E402,F401 - the test extra installs ur_rtde; a missing one must fail, not skip
from loopback_helpers import FakeSkin  # noqa: E402
from timing import unless_the_feed_stalled  # noqa: E402

from aptkt.robot import Placement, SafetyLimits  # noqa: E402
from aptkt.sim.loopback import contact as contact_models  # noqa: E402


def test_the_ur10_presses_a_simulated_world_object_through_ur_rtde(healthy_robot, loopback, feed):
    unless_the_feed_stalled(
        feed, lambda: _presses(healthy_robot(), loopback), SafetyLimits().watchdog_timeout
    )


def _presses(robot, loopback) -> None:
    spec = {"type": "sim_object", "object": "rough_sponge", "x": 0.0, "y": -0.5}
    model = contact_models.build(spec)
    top = model.shape.surface_z
    loopback.set_contact(spec)
    loopback.reset(pose=(0.0, -0.5, top + 0.006, math.pi, 0.0, 0.0), keep_program=True)
    sponge = Placement(
        "rough_sponge", 0.0, -0.5, top, (-0.06, -0.54, top - 0.01), (0.06, -0.46, top + 0.04)
    )
    robot.move_above(sponge, 0.004)
    skin = FakeSkin(loopback)
    z = robot.approach_contact(skin, 0.05)
    robot.press(0.001, 0.2)
    state = loopback.state()
    assert state["pose"][2] == pytest.approx(z - 0.001, abs=1e-6)
    assert state["normal_force"] == pytest.approx(model.normal_force(state["pose"]), rel=1e-9)
    assert 0.3 < state["normal_force"] < 1.5
    robot.lift(0.005)
