"""The workspace file: object placements, limits and the robot section, with clear errors."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aptkt.errors import ConfigError
from aptkt.robot import UR10, SafetyLimits, load_workspace
from aptkt.robot.workspace import DEFAULT_TOOL_ORIENTATION, parse_workspace

EXAMPLE = """
[robot]
host = "192.168.1.10"
tool_orientation = [3.14159265, 0.0, 0.0]
workspace_min = [-0.8, -0.9, -0.02]
workspace_max = [0.8, -0.2, 0.6]

[robot.limits]
max_normal_force = 3.0
approach_speed = 0.004

[[object]]
name = "sponge"
x = 0.10
y = -0.55
surface_z = 0.031
workspace_min = [0.05, -0.60, 0.00]
workspace_max = [0.15, -0.50, 0.20]
slide_direction = [0.0, 2.0]

[[object]]
name = "cork"
x = -0.10
y = -0.55
surface_z = 0.02
workspace_min = [-0.15, -0.60, 0.00]
workspace_max = [-0.05, -0.50, 0.20]
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cell.toml"
    path.write_text(textwrap.dedent(text))
    return path


def test_example_file(tmp_path):
    cfg = load_workspace(write(tmp_path, EXAMPLE))
    assert cfg.host == "192.168.1.10"
    assert cfg.limits == SafetyLimits(max_normal_force=3.0, approach_speed=0.004)
    assert cfg.workspace == ((-0.8, -0.9, -0.02), (0.8, -0.2, 0.6))
    assert set(cfg.placements) == {"sponge", "cork"}
    sponge = cfg.placement("sponge")
    assert (sponge.x, sponge.y, sponge.surface_z) == (0.10, -0.55, 0.031)
    assert sponge.slide_direction == (0.0, 1.0)  # normalised
    assert cfg.placement("cork").slide_direction == (1.0, 0.0)  # the default
    assert cfg.tool_orientation == (3.14159265, 0.0, 0.0)


def test_minimal_file_uses_defaults(tmp_path):
    cfg = load_workspace(
        write(
            tmp_path,
            """
        [[object]]
        name = "a"
        x = 0
        y = 0
        surface_z = 0
        workspace_min = [-1, -1, -1]
        workspace_max = [1, 1, 1]
    """,
        )
    )
    assert cfg.host is None and cfg.workspace is None
    assert cfg.limits == SafetyLimits() and cfg.tool_orientation == DEFAULT_TOOL_ORIENTATION


OBJECT = """
[[object]]
name = "a"
x = 0.0
y = 0.0
surface_z = 0.0
workspace_min = [-0.1, -0.1, -0.1]
workspace_max = [0.1, 0.1, 0.1]
"""


@pytest.mark.parametrize(
    "text, message",
    [
        ("[robot]\nhost = 3\n", "robot.host must be a non-empty string"),
        ("[robot]\nspeed = 3\n", r"\[robot\]: unknown key\(s\) \['speed'\]"),
        ("[robots]\n", r"unknown top-level key\(s\) \['robots'\]"),
        ("[robot.limits]\nmax_force = 1.0\n", r"robot.limits: unknown key\(s\) \['max_force'\]"),
        ("[robot.limits]\nmax_speed = -1.0\n", "robot.limits: SafetyLimits.max_speed must be > 0"),
        ("[robot.limits]\nmax_speed = true\n", "robot.limits.max_speed must be a finite number"),
        (
            "[robot]\ntool_orientation = [1, 2]\n",
            "robot.tool_orientation must be a list of 3 numbers",
        ),
        ("[robot]\nworkspace_min = [0, 0, 0]\n", "workspace_min and workspace_max go together"),
        ("[[object]]\nx = 1\n", "object #1: needs a non-empty 'name'"),
        (OBJECT.replace("x = 0.0\n", ""), "object 'a': missing 'x'"),
        (OBJECT.replace("y = 0.0", "y = nan"), "object 'a': y must be a finite number, got nan"),
        (OBJECT.replace("y = 0.0", 'y = "0"'), "object 'a': y must be a finite number"),
        (OBJECT + "colour = 'red'\n", r"object 'a': unknown key\(s\) \['colour'\]"),
        (OBJECT + OBJECT, "object 'a': defined twice"),
        (
            OBJECT.replace("[0.1, 0.1, 0.1]", "[0.1, -0.2, 0.1]"),
            "workspace_min.y .* must be below workspace_max.y",
        ),
        (
            OBJECT.replace("surface_z = 0.0", "surface_z = 0.5"),
            r"surface point \(0.0, 0.0, 0.5\) lies outside",
        ),
        (OBJECT + "slide_direction = [0, 0]\n", "slide_direction must not be zero"),
        (OBJECT + "slide_direction = [1, 0, 0]\n", "slide_direction must be a list of 2 numbers"),
        (
            "[robot]\nworkspace_min = [-0.05, -1, -1]\nworkspace_max = [1, 1, 1]\n" + OBJECT,
            "its workspace box is not inside the robot workspace box",
        ),
    ],
)
def test_every_problem_is_a_config_error_naming_file_and_field(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=message) as err:
        load_workspace(path)
    assert str(err.value).startswith(str(path))


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(ConfigError, match="workspace file not found"):
        load_workspace(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_workspace(write(tmp_path, "[[object]\nname="))


def test_unknown_object_name(tmp_path):
    cfg = load_workspace(write(tmp_path, EXAMPLE))
    with pytest.raises(ConfigError, match=r"no object named 'glass' \(known: cork, sponge\)"):
        cfg.placement("glass")


def test_ur10_from_config_needs_a_host(tmp_path):
    path = write(tmp_path, OBJECT)
    with pytest.raises(ConfigError, match="no robot host given"):
        UR10.from_config(path)
    robot = UR10.from_config(path, host="10.0.0.2", connect=False)
    assert robot.host == "10.0.0.2" and set(robot.placements) == {"a"}
    assert not robot.connected
    from_file = UR10.from_config(write(tmp_path, EXAMPLE), connect=False)
    assert from_file.host == "192.168.1.10" and from_file.limits.max_normal_force == 3.0
    assert from_file.workspace == ((-0.8, -0.9, -0.02), (0.8, -0.2, 0.6))


coordinate = st.floats(-1.0, 1.0, allow_nan=False)


@given(
    point=st.tuples(coordinate, coordinate, coordinate),
    lo=st.tuples(coordinate, coordinate, coordinate),
    size=st.tuples(*[st.floats(1e-3, 1.0)] * 3),
)
def test_a_placement_is_accepted_exactly_when_its_point_is_in_its_box(point, lo, size):
    hi = tuple(a + s for a, s in zip(lo, size))
    doc = {
        "object": [
            {
                "name": "o",
                "x": point[0],
                "y": point[1],
                "surface_z": point[2],
                "workspace_min": list(lo),
                "workspace_max": list(hi),
            }
        ]
    }
    inside = all(a <= p <= b for a, p, b in zip(lo, point, hi))
    if inside:
        placement = parse_workspace(doc).placements["o"]
        assert placement.contains(point)
        assert math.isclose(math.hypot(*placement.slide_direction), 1.0)
    else:
        with pytest.raises(ConfigError, match="lies outside its workspace box"):
            parse_workspace(doc)
