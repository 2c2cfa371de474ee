"""The simulated arm: the Robot interface on simulated time, and safety limits enforced where a
real arm must stop."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from aptkt.actions import PAPER_ACTIONS, ExplorationSettings, ExploratoryAction, Movement, explore
from aptkt.errors import RobotError, SafetyLimitError, TrialFault
from aptkt.robot.base import Robot, SafetyLimits
from aptkt.sim import RecordingDrift, SimWorld

FAST = ExplorationSettings(thermal_wait=0.0, stamp_wall_clock=False)


def total_forces(rec) -> np.ndarray:
    """The skin's total normal force after every packet (latest value per cell, summed)."""
    s = rec.samples
    latest = {}
    out = []
    for cid, f in zip(s.cell_id, s.force.sum(axis=1)):
        latest[int(cid)] = f
        out.append(sum(latest.values()))
    return np.array(out)


def test_implements_the_robot_protocol(world):
    with world.session("towel") as s:
        assert isinstance(s.robot, Robot)


def test_simulated_time_costs_no_wall_clock(world):
    act = PAPER_ACTIONS["C1"]
    with world.session("wooden_board", "C1", 0, action=act) as s:
        t0, w0 = s.robot.now_ns(), time.perf_counter()
        rec = explore(s.robot, s.skin, s.placement, act, settings=replace(FAST, thermal_wait=30.0))
        simulated = (s.robot.now_ns() - t0) * 1e-9
        wall = time.perf_counter() - w0
    assert rec.duration == pytest.approx(15.0, abs=0.01)
    assert simulated > 45.0 and wall < simulated / 5


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda r, sk: r.press(0.006, 1.0), "depth"),
        (lambda r, sk: r.slide(0.1, 0.2, 1.0, (1.0, 0.0), sk.total_normal_force), "speed"),
        (lambda r, sk: r.slide(6.0, 0.01, 1.0, (1.0, 0.0), sk.total_normal_force), "force"),
        (lambda r, sk: r.slide(0.1, 0.01, 30.0, (1.0, 0.0), sk.total_normal_force), "workspace"),
    ],
)
def test_requests_beyond_limits_are_refused_before_moving(world, call, match):
    with world.session("metal_toolbox") as s:
        s.robot.move_above(s.placement, 0.003)
        s.robot.approach_contact(s.skin.total_normal_force, 0.05)
        before, _ = s.engine.tcp()
        with pytest.raises(SafetyLimitError, match=match):
            call(s.robot, s.skin)
        after, _ = s.engine.tcp()
        assert np.allclose(before, after)


def test_move_outside_the_workspace_is_refused(world):
    with world.session("towel") as s:
        bad = replace(
            s.placement, workspace_max=(s.placement.x + 0.01, 1.0, s.placement.surface_z + 0.001)
        )
        with pytest.raises(SafetyLimitError, match="workspace"):
            s.robot.move_above(bad, 0.01)


def test_force_limit_stops_the_press_at_the_crossing():
    limit = 1.0
    world = SimWorld(seed=5, limits=SafetyLimits(max_normal_force=limit))
    act = PAPER_ACTIONS["P2"]  # about 3.4 N on metal
    with world.session("metal_toolbox", "P2", 0, action=act) as s:
        with pytest.raises(TrialFault, match="SafetyLimitError: .*force") as err:
            explore(s.robot, s.skin, s.placement, act, settings=FAST)
        assert isinstance(err.value.cause, SafetyLimitError) and not err.value.complete
        rec = err.value.recording
        peak = total_forces(rec).max()
        # It did get there, and stopped within one control tick of ramping (5 mm/s * 8 ms).
        assert limit - 0.1 < peak < limit + 0.15
        pos, _ = s.engine.tcp()
        assert s.engine.wrench() == 0.0 and pos[2] > rec.metadata["contact_z"]  # retracted


def test_force_control_depth_limit():
    world = SimWorld(seed=5, limits=SafetyLimits(max_depth=0.0015))
    act = ExploratoryAction(
        "hard_slide", Movement.SLIDE, normal_force=3.0, speed=0.01, slide_time=1.0
    )
    with world.session("rough_sponge", "hard_slide", 0, action=act) as s:
        with pytest.raises(TrialFault, match="SafetyLimitError: .*max_depth"):
            explore(s.robot, s.skin, s.placement, act, settings=FAST)


def test_no_contact_within_travel_is_an_error(world):
    with world.session("towel") as s:
        # The robot is told the surface is 8 cm higher than it is.
        wrong = replace(
            s.placement, surface_z=s.placement.surface_z + 0.08, workspace_max=(1.0, 1.0, 1.0)
        )
        with pytest.raises(RobotError, match="no contact"):
            explore(s.robot, s.skin, wrong, PAPER_ACTIONS["P1"], settings=FAST)


def test_slide_keeps_the_normal_force(explore):
    for action, target in (("S1", 0.1), ("S3", 0.2)):
        f = total_forces(explore("wooden_board", action))
        assert np.mean(f) == pytest.approx(target, rel=0.1)
        assert np.percentile(np.abs(f - target), 90) < 0.5 * target


def test_lean_force_control_reads_what_the_skin_reads():
    """The fast force loop computes the skin's reading from the packets before they are made;
    reading the skin itself every tick must give the same motion and data."""
    act = PAPER_ACTIONS["S2"]
    recs = []
    for lean in (True, False):
        world = SimWorld(seed=9)
        with world.session("rubber_mat", "S2", 2, action=act) as s:
            s.robot.lean_force_control = lean
            recs.append(explore(s.robot, s.skin, s.placement, act, trial=2, settings=FAST))
    a, b = (r.samples for r in recs)
    assert np.array_equal(a.t_ns, b.t_ns) and np.array_equal(a.force, b.force)
    assert np.array_equal(a.proximity, b.proximity)
    # Heat and stick-slip are integrated over differently sized steps: equal to the last bit of
    # the wire's resolution (rare rounding flips).
    assert np.abs(a.temp - b.temp).max() <= 0.5 + 1e-9 and np.mean(a.temp != b.temp) < 1e-3
    assert np.abs(a.acc - b.acc).max() <= 2 / 256 and np.mean(a.acc != b.acc) < 1e-3


@pytest.mark.parametrize(
    ("obj", "action"),
    [("rough_sponge", "S1"), ("ceramic_tile", "S4"), ("towel", "P1"), ("metal_toolbox", "C1")],
)
def test_native_force_loop_matches_the_python_loop(obj, action):
    """The guarded approach and the slide's force loop in the compiled core tick exactly as the
    Python loops reading the skin: the same recording to the last bit."""
    act = PAPER_ACTIONS[action]
    recs = []
    for native in (True, False):
        world = SimWorld(seed=3)
        with world.session(obj, action, 1, action=act) as s:
            s.robot.native_force_loop = native
            recs.append(explore(s.robot, s.skin, s.placement, act, trial=1, settings=FAST))
    a, b = (r.samples for r in recs)
    assert len(a) > 1000
    for field in ("cell_id", "t_ns", "force", "acc", "temp", "proximity"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    assert recs[0].metadata["contact_z"] == recs[1].metadata["contact_z"]


@pytest.mark.parametrize("native", [True, False])
def test_force_limit_stops_the_slide_in_either_loop(native):
    # Without the recording's drift, so that the skin's calibration holds and the loop's
    # overshoot (not a sensor reading low) is what carries the true force past the limit.
    world = SimWorld(seed=5, limits=SafetyLimits(max_normal_force=1.0), drift=RecordingDrift.off())
    act = ExploratoryAction("pushy", Movement.SLIDE, normal_force=0.99, speed=0.01, slide_time=1.0)
    with world.session("metal_toolbox", "pushy", 0, action=act) as s:
        s.robot.native_force_loop = native
        s.robot.force_gain = 0.5  # an aggressive loop overshoots the 1 N limit
        with pytest.raises(TrialFault, match="SafetyLimitError: .*under force control"):
            explore(s.robot, s.skin, s.placement, act, settings=FAST)
        assert s.engine.wrench() == 0.0  # retracted


def test_ctrl_c_in_the_thermal_wait_carries_the_whole_recording_out(monkeypatch):
    """The action finished and the skin stopped recording; a Ctrl-C while lifting off or
    waiting for the temperature sensors must not lose that recording: it leaves as a complete
    TrialInterrupted, which the collectors store as a finished trial."""
    from aptkt.errors import TrialInterrupted

    world = SimWorld(seed=5)
    act = PAPER_ACTIONS["P1"]
    with world.session("towel", "P1", 0, action=act) as s:

        def interrupted(seconds: float) -> None:
            raise KeyboardInterrupt

        monkeypatch.setattr(s.robot, "wait", interrupted)
        with pytest.raises(TrialInterrupted) as err:
            explore(s.robot, s.skin, s.placement, act, settings=FAST)
    assert err.value.complete and isinstance(err.value.__cause__, KeyboardInterrupt)
    rec = err.value.recording
    assert len(rec.samples) > 0 and "aborted" not in rec.metadata
