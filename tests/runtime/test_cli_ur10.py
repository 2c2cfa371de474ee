"""``aptkt collect --robot ur10`` and ``aptkt learn --robot ur10`` end to end: the real ur_rtde
client drives the loopback controller, whose simulated skin streams through a pty that the
real SerialSkin reads — hardware in the loop on one machine."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import rtde_control  # noqa: E402,F401 - the test extra installs ur_rtde; a missing one must fail, not skip
from loopback_helpers import free_loopback_host  # noqa: E402

from aptkt.cli import main  # noqa: E402
from aptkt.data import DatasetReader  # noqa: E402
from aptkt.learning import PriorKnowledge  # noqa: E402
from aptkt.learning.dataset import load_observations  # noqa: E402
from aptkt.sim.loopback import Loopback  # noqa: E402

DOWN = (math.pi, 0.0, 0.0)
START = (0.0, -0.5, 0.02, *DOWN)
STIFFNESS = {"block_a": 200.0, "block_b": 500.0}  # N/m
DEPTH = 0.001  # the action's press depth (m)
ACTIONS = """
[[action]]
name = "Pq"
movement = "press"
depth = 0.001
hold_time = 0.4
"""


def cell_toml(host: str) -> str:
    # Slow approach and short approach travel keep the tests short; the rest are the defaults.
    text = f'[robot]\nhost = "{host}"\n\n[robot.limits]\napproach_speed = 0.01\nmax_approach_travel = 0.03\n'
    for name, x in (("block_a", -0.03), ("block_b", 0.03)):
        text += (
            f'\n[[object]]\nname = "{name}"\nx = {x}\ny = -0.5\nsurface_z = 0.0\n'
            f"workspace_min = [{x - 0.02}, -0.52, -0.01]\nworkspace_max = [{x + 0.02}, -0.48, 0.04]\n"
        )
    return text


def scene() -> dict:
    """Two spring blocks under the workspace file's placements, of different stiffness."""
    items = []
    for name, x in (("block_a", -0.03), ("block_b", 0.03)):
        items.append(
            {
                "type": "spring",
                "surface_z": 0.0,
                "stiffness": STIFFNESS[name],
                "friction": 0.3,
                "x_range": [x - 0.02, x + 0.02],
                "y_range": [-0.52, -0.48],
            }
        )
    return {"type": "scene", "items": items}


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory):
    d = tmp_path_factory.mktemp("cli_ur10")
    host = free_loopback_host()
    (d / "cell.toml").write_text(cell_toml(host))
    (d / "actions.toml").write_text(ACTIONS)
    # The shipped patch with a longer silence timeout: a loaded test machine may stall the
    # loopback's process for a tenth of a second, which is not what these tests are about.
    from aptkt.skin.config import default_patch

    src = Path(default_patch().source).read_text()
    (d / "patch.toml").write_text(src.replace("silence_timeout_s = 0.1", "silence_timeout_s = 0.4"))
    lb = Loopback(
        host,
        contact=scene(),
        skin={"patch": str(d / "patch.toml")},
        start_pose=START,
        unlock_delay=0.0,
    )
    with lb:
        yield d, lb


def run_cli(cell, command: str, *args: str) -> int:
    d, lb = cell
    lb.reset(pose=START)
    return main(
        [
            command,
            "--robot",
            "ur10",
            "--workspace",
            str(d / "cell.toml"),
            "--skin",
            lb.skin_port,
            "--patch",
            str(d / "patch.toml"),
            "--actions-file",
            str(d / "actions.toml"),
            "--actions",
            "Pq",
            "--thermal-wait",
            "0",
            *args,
        ]
    )


def on_press(lb: Loopback, nth: int, action: Callable[[], object]) -> threading.Thread:
    """Call ``action`` once the arm presses for the ``nth`` time from now: a fault in the middle
    of that trial's recording. Pressing = the TCP 0.7 mm below the surfaces, deeper than the
    guarded approach ever overshoots the light contact (0.3 mm at most on block_b)."""

    def watch() -> None:
        pressing, seen = True, 0  # a press going on already (after a fault) does not count
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline:
            z = lb.state()["pose"][2]
            if z < -0.0007 and not pressing:
                pressing, seen = True, seen + 1
                if seen == nth:
                    action()
                    return
            elif z > 0.001:
                pressing = False  # lifted off: the next press is a new one
            time.sleep(0.01)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def test_collect_survives_faults_and_resumes_to_a_complete_data_set(cell, capsys):
    d, lb = cell
    data = d / "data.h5"
    common = ("--objects", "block_a,block_b", "-o", str(data), "--no-progress")
    assert run_cli(cell, "collect", *common, "-n", "1") == 0
    with DatasetReader(data) as rd:
        assert sorted(rd.keys()) == [("block_a", "Pq", 0), ("block_b", "Pq", 0)]
        for rec in rd:
            meta = rec.metadata
            assert meta["skin"] == "SerialSkin" and meta["robot"] == "UR10" and not rec.silent_cells
            assert rec.duration == pytest.approx(0.4, abs=0.02)
            # Every cell streams through the pty (250 Hz of controller time; a starved loopback
            # process runs its clock late, so a loaded machine sees fewer per wall-clock second).
            per_cell = np.bincount(rec.samples.cell_id.astype(int), minlength=8)[1:]
            assert per_cell.min() >= 0.5 * 250 * 0.4 and per_cell.max() <= 1.1 * 250 * 0.4
            # The skin's force against the robot's own trace: the spring law of the block touched.
            trace = meta["robot_trace"]  # the whole movement: keep the recorded window
            host = np.array(trace["host_t_ns"])
            z = np.array(trace["tcp_pose"])[(host >= rec.start_ns) & (host < rec.stop_ns), 2]
            total = rec.samples.force.sum(axis=1).mean() * len(rec.cells)
            assert total == pytest.approx(STIFFNESS[meta["object"]] * -z.mean(), abs=0.03)
            assert total == pytest.approx(STIFFNESS[meta["object"]] * DEPTH + 0.05, abs=0.06)
    capsys.readouterr()

    # A protective stop in the middle of the second new trial (block_b, trial 1).
    watcher = on_press(lb, 2, lambda: lb.protective_stop("injected: collision"))
    assert run_cli(cell, "collect", *common, "-n", "3", "--resume") == 3
    watcher.join(timeout=5.0)
    err = capsys.readouterr().err
    assert "block_b / Pq / trial 1: ProtectiveStopError" in err and "--resume" in err
    assert not lb.state()["moving"]
    with DatasetReader(data) as rd:  # every completed trial is readable
        assert sorted(rd.keys()) == [
            ("block_a", "Pq", 0),
            ("block_a", "Pq", 1),
            ("block_b", "Pq", 0),
        ]
    aborted = d / "data.aborted.h5"
    with DatasetReader(aborted) as rd:
        assert rd.keys() == [("block_b", "Pq", 1)]
        partial = rd.recording(0)
    assert "ProtectiveStopError" in partial.metadata["aborted"]
    assert len(partial.samples) > 0 and partial.metadata["robot_trace"]["tcp_pose"]

    # The skin goes silent in the middle of the next trial (block_b, trial 1 again).
    watcher = on_press(lb, 1, lambda: lb.silence_skin())
    assert run_cli(cell, "collect", *common, "-n", "3", "--resume") == 3
    watcher.join(timeout=5.0)
    err = capsys.readouterr().err
    assert "block_b / Pq / trial 1: SilentCellError" in err
    with DatasetReader(d / "data.aborted-2.h5") as rd:  # the same trial's second partial recording
        assert rd.keys() == [("block_b", "Pq", 1)]
    # A silent patch stops the next run before the arm moves.
    assert run_cli(cell, "collect", *common, "-n", "3", "--resume") == 1
    assert "no data from cell(s)" in capsys.readouterr().err

    lb.restore_skin()  # the operator fixed the faults
    assert run_cli(cell, "collect", *common, "-n", "3", "--resume") == 0
    with DatasetReader(data) as rd:
        assert sorted(rd.keys()) == [(o, "Pq", t) for o in ("block_a", "block_b") for t in range(3)]
        assert all(not rec.metadata.get("aborted") for rec in rd)


@pytest.fixture(scope="module")
def prior_npz(cell) -> Path:
    """Prior knowledge of the same action on objects of the simulated world."""
    d, _ = cell
    prior_data = d / "prior.h5"
    assert (
        main(
            [
                "collect",
                "--robot",
                "sim",
                "--actions-file",
                str(d / "actions.toml"),
                "--actions",
                "Pq",
                "--objects",
                "rough_sponge,paper_box,metal_toolbox",
                "-n",
                "3",
                "-o",
                str(prior_data),
                "--thermal-wait",
                "0",
                "--no-progress",
            ]
        )
        == 0
    )
    PriorKnowledge.build(load_observations(prior_data)).save(d / "prior.npz")
    return d / "prior.npz"


def test_learn_runs_live_through_the_loopback(cell, prior_npz, capsys):
    d, lb = cell
    capsys.readouterr()
    out = d / "learn"
    assert (
        run_cli(
            cell,
            "learn",
            "--prior",
            str(prior_npz),
            "--objects",
            "block_a,block_b",
            "--budget",
            "1",
            "-o",
            str(out),
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "no test set" in text and "step   1/1: Pq on block_" in text
    with DatasetReader(out / "recordings.h5") as rd:
        assert len(rd) == 3
        assert all(rec.metadata["robot"] == "UR10" for rec in rd)
    learned = PriorKnowledge.load(out / "learned_prior.npz")
    obs = learned["Pq"].observations
    force = {o: obs.modalities["force"][obs.objects == o].mean() for o in ("block_a", "block_b")}
    # The force feature (mean over the 21 sensors) follows each block's spring law.
    for name, f in force.items():
        assert f * 21 == pytest.approx(STIFFNESS[name] * DEPTH + 0.05, abs=0.06)


@pytest.mark.parametrize(
    ("sig", "code", "word"),
    [(signal.SIGTERM, 143, "terminated (SIGTERM)"), (signal.SIGINT, 130, "interrupted")],
    ids=["SIGTERM", "SIGINT"],
)
def test_a_signal_mid_press_retracts_and_keeps_the_data(cell, sig, code, word):
    """SIGTERM and Ctrl-C in the middle of a press: the arm stops and retracts (no force left on
    the object), the completed trial and the partial recording are kept, one message, 143/130."""
    d, lb = cell
    lb.reset(pose=START)
    data = d / f"signal-{sig.name}.h5"
    argv = [
        "collect", "--robot", "ur10", "--workspace", str(d / "cell.toml"), "--skin", lb.skin_port,
        "--patch", str(d / "patch.toml"), "--actions-file", str(d / "actions.toml"),
        "--actions", "Pq", "--thermal-wait", "0", "--objects", "block_a,block_b", "-n", "1",
        "-o", str(data), "--no-progress",
    ]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2] / "python")}
    # In a process group of its own, signalled as a terminal's Ctrl-C or a job's end is: the
    # whole group (the control client's process must not take the signal and leave the arm).
    proc = subprocess.Popen(
        [sys.executable, "-m", "aptkt.cli", *argv],
        env=env,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    # In the middle of the second press (block_b, trial 0), after block_a's trial completed.
    watcher = on_press(lb, 2, lambda: os.killpg(proc.pid, sig))
    _, err = proc.communicate(timeout=180)
    watcher.join(timeout=5.0)
    assert proc.returncode == code, (err, lb.state()["text_log"][-15:])
    assert word in err and "Traceback" not in err, err
    assert "block_b / Pq / trial 0" in err, err
    time.sleep(0.2)
    state = lb.state()
    assert not state["moving"] and state["normal_force"] == 0.0, state
    assert state["pose"][2] > 0.003, state  # lifted off the object
    with DatasetReader(data) as rd:
        assert rd.keys() == [("block_a", "Pq", 0)]
    with DatasetReader(d / f"signal-{sig.name}.aborted.h5") as rd:
        assert rd.keys() == [("block_b", "Pq", 0)]
        assert len(rd.recording(0).samples) > 0


@pytest.mark.parametrize(
    ("sig", "code", "word"),
    [(signal.SIGTERM, 143, "terminated (SIGTERM)"), (signal.SIGINT, 130, "interrupted")],
    ids=["SIGTERM", "SIGINT"],
)
def test_a_signal_mid_press_during_learn_retracts_and_keeps_the_data(
    cell, prior_npz, sig, code, word
):
    """``aptkt learn`` takes the same path as collect: the arm stops and retracts, the completed
    recording and the partial one are kept, the run so far is written, one message, 143/130."""
    d, lb = cell
    lb.reset(pose=START)
    out = d / f"learn-signal-{sig.name}"
    argv = [
        "learn", "--robot", "ur10", "--workspace", str(d / "cell.toml"), "--skin", lb.skin_port,
        "--patch", str(d / "patch.toml"), "--actions-file", str(d / "actions.toml"),
        "--actions", "Pq", "--thermal-wait", "0", "--prior", str(prior_npz),
        "--objects", "block_a,block_b", "--budget", "1", "-o", str(out),
    ]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2] / "python")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "aptkt.cli", *argv],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # signalled as a group, as in the collect test
    )
    # In the middle of the second press of the initial round, after the first completed.
    watcher = on_press(lb, 2, lambda: os.killpg(proc.pid, sig))
    _, err = proc.communicate(timeout=180)
    watcher.join(timeout=5.0)
    assert proc.returncode == code, (err, lb.state()["text_log"][-15:])
    lines = [line for line in err.splitlines() if line.startswith("aptkt learn:")]
    assert len(lines) == 1 and word in lines[0] and "Traceback" not in err, err
    assert "/ Pq / trial 0" in lines[0] and "aborted" in lines[0], err
    time.sleep(0.2)
    state = lb.state()
    assert not state["moving"] and state["normal_force"] == 0.0, state
    assert state["pose"][2] > 0.003, state  # lifted off the object
    with DatasetReader(out / "recordings.h5") as rd:
        assert len(rd) == 1
        (done,) = rd.keys()
    with DatasetReader(out / "recordings.aborted.h5") as rd:
        (partial,) = rd.keys()
        assert len(rd.recording(0).samples) > 0
    assert {done[0], partial[0]} == {"block_a", "block_b"}
    run = json.loads((out / "run.json").read_text())
    assert run["status"].startswith("aborted: ") and run["fault"]["object"] == partial[0]


def test_a_dropped_link_mid_press_is_a_fault_that_keeps_the_data(cell, capsys):
    d, lb = cell
    data = d / "dropped.h5"
    watcher = on_press(lb, 2, lambda: lb.drop_connections())
    args = ("--objects", "block_a,block_b", "-n", "1", "-o", str(data), "--no-progress")
    assert run_cli(cell, "collect", *args) == 3
    watcher.join(timeout=5.0)
    err = capsys.readouterr().err
    assert "block_b / Pq / trial 0: RobotConnectionError" in err and "--resume" in err, err
    time.sleep(0.7)  # the controller's RTDE watchdog stops the program
    assert not lb.state()["moving"]
    with DatasetReader(data) as rd:
        assert rd.keys() == [("block_a", "Pq", 0)]
    with DatasetReader(d / "dropped.aborted.h5") as rd:
        assert rd.keys() == [("block_b", "Pq", 0)]
    # The link is back: the same command completes the data set.
    assert run_cli(cell, "collect", *args, "--resume") == 0
    with DatasetReader(data) as rd:
        assert sorted(rd.keys()) == [("block_a", "Pq", 0), ("block_b", "Pq", 0)]
