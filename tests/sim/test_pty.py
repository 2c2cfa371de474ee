"""The real-time path: the simulated skin streams the wire protocol through a pty, read by the
unmodified SerialSkin exactly as the USB adapter, while the simulated arm moves in real time."""

from __future__ import annotations

import time

import numpy as np
import pytest
from timing import LatenessProbe, repeat_if_disturbed

from aptkt.actions import PAPER_ACTIONS, ExplorationSettings, explore
from aptkt.errors import SafetyLimitError
from aptkt.skin import SerialSkin

pytestmark = pytest.mark.slow


def test_serial_skin_reads_the_simulated_stream(world):
    with world.session("towel", realtime=True) as s, SerialSkin(s.port, s.patch) as skin:
        skin.wait_for_cells(timeout_s=5.0)
        skin.read()
        time.sleep(1.0)
        samples = skin.read()
        stats = skin.stats
    counts = np.bincount(samples.cell_id)[list(s.patch.cell_ids)]
    assert np.all(counts > 150)  # ~250 per cell and second, minus scheduling jitter
    assert stats["rejected"] == {} or sum(stats["rejected"].values()) == 0
    assert stats["bytes_skipped"] == 0 and not stats["silent_cells"]
    assert samples.acc[:, 2].mean() == pytest.approx(-1.0, abs=0.06)
    assert 25.0 < samples.temp[:, 1].mean() < 35.0
    assert abs(samples.force.sum(axis=1).mean()) < 0.02  # hovering: no load


def test_real_time_press_through_the_pty(world):
    """A press in real time, read through the pty. The arm stops where the skin, read late on a
    busy machine, reports contact; a run this process kept waiting for more than 0.25 s (at the
    approach's 5 mm/s, 1.25 mm deeper: past half the way to the 5 N safety limit, where the run
    stops by design) is no evidence either way and is repeated."""
    act = PAPER_ACTIONS["P1"]
    settings = ExplorationSettings(thermal_wait=0.0, stamp_wall_clock=False)
    probe = LatenessProbe(period=0.005, work=0.001, catch_up=2.0).start()
    since = [0.0]

    def begin() -> None:
        since[0] = time.monotonic()

    def attempt() -> tuple:
        try:
            with (
                world.session("metal_toolbox", "P1", 0, realtime=True, action=act) as s,
                SerialSkin(s.port, s.patch) as skin,
            ):
                skin.wait_for_cells(timeout_s=5.0)
                t0 = time.monotonic()
                rec = explore(s.robot, skin, s.placement, act, settings=settings)
                return rec, time.monotonic() - t0, s.placement
        except SafetyLimitError as exc:
            return exc, 0.0, None

    def check(result: tuple) -> None:
        rec, wall, placement = result
        assert not isinstance(rec, Exception), rec
        assert wall > 3.0  # real time: the 3 s hold takes 3 s
        assert rec.duration == pytest.approx(3.0, abs=0.05) and not rec.silent_cells
        total = rec.grid("force", 250.0).sum(axis=(0, 2))
        fast = world.explore("metal_toolbox", "P1", 0)
        expected = fast.grid("force", 250.0).sum(axis=(0, 2)).mean()
        # On the rigid box the skin's cover sets the force, linear in how far the arm went
        # below the surface: the press's depth plus where the approach stopped, which the
        # recording says (a loaded run stopped 1.6 mm deeper: 2.4 times the force). So the
        # force expected of the real-time run is the fast run's, scaled by the two runs'
        # indentations; a wrong unit, scale or cell mapping would still be far outside.
        below_rt, below_fast = (
            placement.surface_z - r.metadata["contact_z"] + act.depth for r in (rec, fast)
        )
        scaled = expected * below_rt / below_fast
        assert total.mean() == pytest.approx(scaled, rel=0.15), (below_rt, below_fast)

    try:
        repeat_if_disturbed(
            attempt, check, begin=begin, stall=lambda: probe.worst(since[0]), budget=0.25
        )
    finally:
        probe.stop()
