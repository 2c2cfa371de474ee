"""The loopback controller's simulated skin: what it streams, cycle by cycle, and through a pty
to the real SerialSkin."""

from __future__ import annotations

import math
import re
import select
import subprocess
import sys
import time

import numpy as np
import pytest
from loopback_helpers import free_loopback_host
from scipy.spatial.transform import Rotation

from aptkt.sim.loopback import Loopback
from aptkt.sim.loopback.config import CB3_VERSION, E_SERIES_VERSION, ControllerConfig
from aptkt.sim.loopback.controller import SimulatedController
from aptkt.sim.loopback.object_surface import SimObjectSurface
from aptkt.skin import SerialSkin, StreamParser

DOWN = (math.pi, 0.0, 0.0)
QUIET = {
    "force_noise": 0.0,
    "acc_noise": 0.0,
    "temp_noise": 0.0,
    "die_temp_noise": 0.0,
    "proximity_noise": 0.0,
}


class CaptureLink:
    """Stands in for the pty: keeps every byte."""

    def __init__(self) -> None:
        self.data = bytearray()

    def write(self, data: bytes) -> None:
        self.data += data


def controller(
    contact: dict, pose: tuple, *, series: tuple = CB3_VERSION, **skin: object
) -> SimulatedController:
    ctl = SimulatedController(
        ControllerConfig(version=series, contact=contact, start_pose=pose, skin={**QUIET, **skin})
    )
    ctl.skin.link.close()  # the pty is not needed here: capture the bytes instead
    ctl.skin.link = CaptureLink()
    return ctl


def run(ctl: SimulatedController, seconds: float) -> dict[str, np.ndarray]:
    """Tick for ``seconds`` of controller time; the packets streamed meanwhile, parsed."""
    ctl.skin.link.data.clear()
    for _ in range(int(round(seconds / ctl.dt))):
        ctl.tick()
    parser = StreamParser()
    out = parser.feed(bytes(ctl.skin.link.data))
    assert parser.stats["bytes_skipped"] == 0
    return out


def test_every_cell_streams_at_the_configured_rate_whatever_the_control_rate():
    for series in (CB3_VERSION, E_SERIES_VERSION):
        for rate in (250.0, 63.0):
            ctl = controller(
                {"type": "spring"}, (0.0, -0.5, 0.01, *DOWN), series=series, rate_hz=rate
            )
            run(ctl, 0.1)  # the first cycle only starts the clock
            out = run(ctl, 2.0)
            counts = np.bincount(out["cell_id"].astype(int), minlength=8)[1:]
            np.testing.assert_array_equal(counts, round(2.0 * rate))


def test_forces_are_the_contact_models_per_sensor_forces_in_newtons():
    # A spring surface has no per-sensor model: its force is shared by the 21 sensors.
    ctl = controller(
        {"type": "spring", "surface_z": 0.0, "stiffness": 200.0}, (0.0, -0.5, -0.0015, *DOWN)
    )
    run(ctl, 0.05)
    out = run(ctl, 0.2)
    # Default patch calibration: gain 1 N per normalised unit, offset 0 -> the reading is newtons.
    np.testing.assert_allclose(out["force"], 200.0 * 0.0015 / 21, atol=0.5 / 1024)
    # An object of the simulated world: each sensor carries its own indentation.
    pose = (0.01, -0.49, 0.0335, *DOWN)
    ctl = controller({"type": "sim_object", "object": "rough_sponge", "x": 0.0, "y": -0.5}, pose)
    run(ctl, 0.05)
    out = run(ctl, 0.1)
    expected = SimObjectSurface("rough_sponge", 0.0, -0.5).sensor_forces(pose)  # (7, 3)
    assert expected.std() > 0.01 * expected.mean()  # the crown loads the sensors unevenly
    rows = out["cell_id"].astype(int) - 1
    np.testing.assert_allclose(out["force"], expected[rows], atol=0.5 / 1024 + 1e-12)


def test_the_accelerometers_feel_gravity_in_the_tool_frame_and_the_tcps_acceleration():
    ctl = controller({"type": "none"}, (0.0, -0.5, 0.2, *DOWN))
    run(ctl, 0.05)
    out = run(ctl, 0.1)
    np.testing.assert_allclose(out["acc"], [[0.0, 0.0, -1.0]] * len(out["acc"]), atol=0.5 / 256)
    # Any orientation: the reading is gravity's specific force (+1 g up) in the tool's axes.
    rotvec = np.array([0.4, -2.5, 0.7])
    ctl = controller({"type": "none"}, (0.0, -0.5, 0.2, *rotvec))
    run(ctl, 0.05)
    out = run(ctl, 0.1)
    expected = Rotation.from_rotvec(rotvec).inv().apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(out["acc"], np.tile(expected, (len(out["acc"]), 1)), atol=0.5 / 256)
    # Accelerating at 0.5 m/s^2 along base x (tool x for a skin facing down) adds a / g.
    ctl = controller({"type": "none"}, (0.0, -0.5, 0.2, *DOWN))
    run(ctl, 0.05)
    ctl.disturb([0.1, 0.0, 0.0], duration=1.0, acceleration=0.5)
    out = run(ctl, 0.1)
    ramp = out["acc"][len(out["acc"]) // 4 :]  # after the first control cycle of the ramp
    np.testing.assert_allclose(ramp[:, 0], 0.5 / 9.80665, atol=1 / 256)


def test_temperatures_fall_faster_on_metal_than_on_foam():
    lm71 = {}
    for name in ("metal_toolbox", "rough_sponge"):
        ctl = controller(
            {"type": "sim_object", "object": name, "x": 0.0, "y": -0.5}, (0.0, -0.5, 0.2, *DOWN)
        )
        free = run(ctl, 0.5)["temp"]
        # Die 1.5 K above the LM71; the cells warm above the 24 °C room by their electronics.
        np.testing.assert_allclose(free[:, 0] - free[:, 1], 1.5, atol=0.5)
        assert 26.0 < free[:, 1].mean() < 40.0 and free[:, 1].std() < 0.02
        spec = SimObjectSurface(name, 0.0, -0.5)
        ctl.reset(pose=(0.0, -0.5, spec.shape.surface_z - 0.001, *DOWN))
        pressed = run(ctl, 3.0)
        lm71[name] = free[:, 1].mean() - pressed["temp"][-7:, 1].mean()
    assert lm71["metal_toolbox"] > 0.3  # metal draws the heat away: a clear drop in 3 s
    assert lm71["metal_toolbox"] > 3 * lm71["rough_sponge"] > 0  # foam insulates


def test_sliding_on_a_textured_object_shakes_the_accelerometers():
    def vibration(texture: bool, speed: float) -> float:
        pose = (-0.03, -0.5, SimObjectSurface("towel", 0.0, -0.5).shape.surface_z - 0.0005, *DOWN)
        ctl = controller(
            {"type": "sim_object", "object": "towel", "x": 0.0, "y": -0.5}, pose, texture=texture
        )
        run(ctl, 0.05)
        ctl.disturb([speed, 0.0, 0.0], duration=2.0)
        run(ctl, 0.1)
        acc = run(ctl, 0.5)["acc"]
        return float(acc.std(axis=0).max())

    assert vibration(True, 0.0) == 0.0  # no noise configured, nothing moves
    assert vibration(False, 0.05) < 1 / 256  # without texture: steady sliding feels only gravity
    # The towel's weave at 5 cm/s: about 10 mg, as in the simulated world's S2 slides.
    assert vibration(True, 0.05) > 0.008


def test_silenced_cells_send_nothing_until_restored():
    ctl = controller({"type": "spring"}, (0.0, -0.5, 0.01, *DOWN))
    run(ctl, 0.05)
    ctl.skin.silence([3, 5])
    assert set(run(ctl, 0.2)["cell_id"].tolist()) == {1, 2, 4, 6, 7}
    ctl.skin.silence()
    assert len(run(ctl, 0.2)["cell_id"]) == 0
    ctl.skin.restore()
    assert set(run(ctl, 0.2)["cell_id"].tolist()) == set(range(1, 8))
    with pytest.raises(ValueError, match="no cell"):
        ctl.skin.silence([99])


def test_the_real_serial_skin_reads_the_loopbacks_pty():
    with Loopback(
        free_loopback_host(),
        contact={"type": "spring", "surface_z": 0.0, "stiffness": 200.0},
        start_pose=(0.0, -0.5, 0.01, *DOWN),
        skin=True,
    ) as lb:
        assert lb.skin_port and lb.skin_port.startswith("/dev/")
        with SerialSkin(lb.skin_port) as skin:
            skin.wait_for_cells(5.0)
            assert skin.total_normal_force() < 0.05  # noise only, clipped at the zero offset
            lb.reset(pose=(0.0, -0.5, -0.002, *DOWN))
            deadline = time.monotonic() + 5.0
            while abs(skin.total_normal_force() - 0.4) > 0.03 and time.monotonic() < deadline:
                time.sleep(0.02)
            assert skin.total_normal_force() == pytest.approx(lb.normal_force(), abs=0.03)
            lb.silence_skin([2])
            time.sleep(0.5)
            assert skin.silent_cells() == (2,)
            lb.restore_skin()
            skin.wait_for_cells(5.0)
            assert skin.stats["rejected"] == {
                "unknown_header": 0,
                "payload_high_bit": 0,
                "bad_end_marker": 0,
            }
        assert lb.skin_stats()["packets"] > 0


def test_the_command_line_prints_the_skin_pty():
    host = free_loopback_host()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "aptkt.sim.loopback",
            "--host",
            host,
            "--skin-pty",
            "--skin-rate",
            "125",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        port = None
        deadline = time.monotonic() + 30.0
        while port is None and time.monotonic() < deadline:
            ready, _, _ = select.select([proc.stdout], [], [], 1.0)
            if ready:
                line = proc.stdout.readline()
                assert line, proc.stderr.read()
                m = re.search(r"simulated skin .* on (/dev/\S+)", line)
                port = m.group(1) if m else None
        assert port is not None
        with SerialSkin(port) as skin:
            skin.wait_for_cells(5.0)
            time.sleep(1.0)
            rates = skin.stats["rate_hz"]
        assert all(100 < r < 150 for r in rates.values()), rates
    finally:
        proc.terminate()
        proc.wait(timeout=10)
