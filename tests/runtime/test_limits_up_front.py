"""Actions are checked against the cell's safety limits when the files are read, before the
robot is even connected: the error names the action, the parameter, the value and the limit."""

from __future__ import annotations

import pytest

from aptkt.actions import ExploratoryAction, Movement
from aptkt.actions.limits import check_action_limits
from aptkt.cli import main
from aptkt.errors import SafetyLimitError
from aptkt.robot.base import Placement, SafetyLimits

# Nothing listens there: a command that tried to connect would fail with a connection error,
# not with the limit named below.
CELL = """
[robot]
host = "127.0.0.1"

[[object]]
name = "block"
x = 0.0
y = -0.5
surface_z = 0.0
workspace_min = [-0.02, -0.52, -0.01]
workspace_max = [0.02, -0.48, 0.04]
"""

BAD_ACTIONS = {
    "deep": ('movement = "press"\ndepth = 0.010\nhold_time = 1.0', "depth = 0.01 m", "max_depth"),
    "fast": (
        'movement = "slide"\nnormal_force = 0.1\nspeed = 0.5\nslide_time = 0.01',
        "speed = 0.5 m/s",
        "max_speed",
    ),
    "hard": (
        'movement = "slide"\nnormal_force = 20.0\nspeed = 0.01\nslide_time = 0.5',
        "normal_force = 20 N",
        "max_normal_force",
    ),
    "long": (
        'movement = "press"\ndepth = 0.001\nhold_time = 1e9',
        "hold_time = 1e+09 s",
        "max_hold_time",
    ),
    "far": (
        'movement = "slide"\nnormal_force = 0.1\nspeed = 0.01\nslide_time = 5.0',
        "would leave the box of object block",
        "workspace_max",
    ),
}


@pytest.mark.parametrize("name", sorted(BAD_ACTIONS))
def test_limits_are_checked_before_connecting(tmp_path, capsys, name):
    body, value, limit = BAD_ACTIONS[name]
    (tmp_path / "cell.toml").write_text(CELL)
    (tmp_path / "actions.toml").write_text(f'[[action]]\nname = "{name}"\n{body}\n')
    argv = [
        "collect", "--robot", "ur10", "--workspace", str(tmp_path / "cell.toml"),
        "--skin", "/dev/null", "--actions-file", str(tmp_path / "actions.toml"),
        "--actions", name, "--objects", "block", "-n", "1", "-o", str(tmp_path / "d.h5"),
    ]  # fmt: skip
    assert main(argv) == 1
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("aptkt collect: error: "), err
    assert f"action {name}" in lines[0] and value in lines[0] and limit in lines[0]
    assert not (tmp_path / "d.h5").exists()


def test_unused_parameters_are_an_error():
    with pytest.raises(ValueError, match="does not use speed"):
        ExploratoryAction("P", Movement.PRESS, depth=0.001, hold_time=1.0, speed=0.02)
    with pytest.raises(ValueError, match="does not use depth"):
        ExploratoryAction("S", Movement.SLIDE, normal_force=0.1, speed=0.01, slide_time=1, depth=1)


def test_paper_actions_fit_the_default_limits_and_a_roomy_box():
    from aptkt.actions import PAPER_ACTIONS

    box = Placement("o", 0.0, 0.0, 0.0, (-0.1, -0.1, -0.01), (0.1, 0.1, 0.1))
    for action in PAPER_ACTIONS.values():
        check_action_limits(action, SafetyLimits(), [box])
    with pytest.raises(SafetyLimitError, match="action S1: .*box of object o"):
        small = Placement("o", 0.0, 0.0, 0.0, (-0.01, -0.01, -0.01), (0.01, 0.01, 0.1))
        check_action_limits(PAPER_ACTIONS["S1"], SafetyLimits(), [small])


@pytest.fixture(scope="module")
def prior_of_the_bad_names(tmp_path_factory):
    """Prior knowledge of actions named like the bad ones, with parameters within the limits:
    ``learn`` then gets past its prior checks, and only the actions file breaks a limit."""
    from aptkt.learning import PriorKnowledge
    from aptkt.learning.dataset import load_observations
    from aptkt.runtime.generation import GenerationPlan, generate

    d = tmp_path_factory.mktemp("learn_limits")
    press = dict(movement=Movement.PRESS, depth=0.001, hold_time=0.2)
    slide = dict(movement=Movement.SLIDE, normal_force=0.1, speed=0.01, slide_time=0.2)
    actions = tuple(
        ExploratoryAction(name, **(press if "press" in BAD_ACTIONS[name][0] else slide))
        for name in sorted(BAD_ACTIONS)
    )
    objects = ("rough_sponge", "metal_toolbox")
    generate(d / "p.h5", GenerationPlan(objects, actions, 3, seed=1), progress=False)
    PriorKnowledge.build(load_observations(d / "p.h5")).save(d / "p.npz")
    return d / "p.npz"


@pytest.fixture(scope="module")
def loopback():
    """A live loopback controller with its pty skin: a command that moved the arm would be seen."""
    from loopback_helpers import free_loopback_host

    from aptkt.sim.loopback import Loopback

    with Loopback(free_loopback_host(), skin={}, unlock_delay=0.0) as lb:
        yield lb


@pytest.mark.parametrize("name", sorted(BAD_ACTIONS))
def test_learn_checks_the_limits_before_connecting(
    tmp_path, capsys, prior_of_the_bad_names, loopback, name
):
    body, value, limit = BAD_ACTIONS[name]
    cell = CELL.replace('"127.0.0.1"', f'"{loopback.host}"')
    (tmp_path / "cell.toml").write_text(
        cell + cell[cell.index("[[object]]") :].replace('"block"', '"block2"')
    )
    (tmp_path / "actions.toml").write_text(f'[[action]]\nname = "{name}"\n{body}\n')
    before = loopback.state()
    argv = [
        "learn", "--robot", "ur10", "--workspace", str(tmp_path / "cell.toml"),
        "--skin", loopback.skin_port, "--prior", str(prior_of_the_bad_names),
        "--actions-file", str(tmp_path / "actions.toml"), "--actions", name,
        "--objects", "block,block2", "--budget", "1", "-o", str(tmp_path / "out"),
    ]  # fmt: skip
    assert main(argv) == 1
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("aptkt learn: error: "), err
    assert f"action {name}" in lines[0] and value in lines[0] and limit in lines[0]
    assert not (tmp_path / "out").exists()
    after = loopback.state()  # never connected, never moved
    assert not after["connections"] and after["pose"] == before["pose"], after


@pytest.mark.parametrize(
    ("option", "value", "fragment"),
    [
        ("--thermal-wait", "inf", "--thermal-wait must be at most 3600"),
        ("--workspace", "binary", "not a workspace file"),
        ("--repetitions", "100000000", "more than the 100000"),
    ],
)
def test_collect_refuses_before_the_arm_moves(tmp_path, capsys, loopback, option, value, fragment):
    """An infinite --thermal-wait used to fail only after the first press (the arm moved, and
    the trial's recording was lost); a binary workspace file was a UnicodeDecodeError."""
    cell = tmp_path / "cell.toml"
    cell.write_text(CELL.replace('"127.0.0.1"', f'"{loopback.host}"'))
    args = {"--workspace": str(cell), "--thermal-wait": "0", "--repetitions": "1"}
    if value == "binary":
        value = str(tmp_path / "prior.npz")
        (tmp_path / "prior.npz").write_bytes(bytes(range(256)) * 4)
    args[option] = value
    before = loopback.state()
    argv = [
        "collect", "--robot", "ur10", "--skin", loopback.skin_port, "--objects", "block",
        "--actions", "P1", "-o", str(tmp_path / "d.h5"),
        *(x for item in args.items() for x in item),
    ]  # fmt: skip
    assert main(argv) == 1
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("aptkt collect: error: "), err
    assert fragment in lines[0]
    assert not (tmp_path / "d.h5").exists()
    after = loopback.state()  # never connected, never moved
    assert not after["connections"] and after["pose"] == before["pose"], after


def test_exploration_settings_refuse_an_endless_wait():
    from aptkt.actions import ExplorationSettings

    for value in (float("inf"), float("nan"), -1.0):
        with pytest.raises(ValueError, match="thermal_wait must be a finite number >= 0"):
            ExplorationSettings(thermal_wait=value)


def test_a_bool_in_the_limits_is_not_a_number():
    from aptkt.errors import ConfigError
    from aptkt.robot.workspace import parse_workspace

    with pytest.raises(ConfigError, match="robot.limits.max_hold_time must be a finite number"):
        parse_workspace({"robot": {"limits": {"max_hold_time": True}}}, source="cell.toml")
