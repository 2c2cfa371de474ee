"""Patch files: the shipped default, calibration maths, and errors that name file and field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from aptkt.errors import ConfigError
from aptkt.skin import ForceCalibration, PatchConfig, default_patch, load_patch

GOOD = """
[patch]
name = "test-patch"
silence_timeout_s = 0.2
force_offset = 0.1
force_gain = [1.0, 2.0, 4.0]

[[cell]]
id = 10
position_mm = [0.0, 0.0, 0.0]

[[cell]]
id = 20
position_mm = [15.0, 0.0, 0.0]
force_offset = [0.0, 0.5, 1.0]
force_gain = 3.0
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "patch.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_default_patch_has_seven_distinct_cells_in_a_hexagon():
    patch = default_patch()
    assert len(patch.cells) == 7 and len(set(patch.cell_ids)) == 7
    pos = patch.positions_mm
    # a centre and six neighbours at the same distance
    d = np.sort(np.linalg.norm(pos - pos[0], axis=1))
    assert d[0] == 0 and np.allclose(d[1:], d[1])
    assert patch.silence_timeout_s > 0
    assert patch.source is not None and patch.source.endswith("patch_7cells.toml")


def test_loading_with_defaults_and_overrides(tmp_path):
    patch = load_patch(write(tmp_path, GOOD))
    assert (
        patch.name == "test-patch" and patch.cell_ids == (10, 20) and patch.silence_timeout_s == 0.2
    )
    cal = patch.calibration()
    np.testing.assert_array_equal(cal.offset, [[0.1, 0.1, 0.1], [0.0, 0.5, 1.0]])
    np.testing.assert_array_equal(cal.gain, [[1.0, 2.0, 4.0], [3.0, 3.0, 3.0]])
    # newtons = gain * (normalised - offset)
    cells = np.array([20, 10, 20])
    norm = np.array([[1.0, 1.0, 1.0], [0.6, 0.6, 0.6], [0.0, 0.5, 2.0]])
    newtons = cal.to_newtons(cells, norm)
    np.testing.assert_allclose(newtons, [[3.0, 1.5, 0.0], [0.5, 1.0, 2.0], [0.0, 0.0, 3.0]])
    np.testing.assert_allclose(cal.to_normalised(cells, newtons), norm)
    with pytest.raises(ValueError, match=r"\[99\]"):
        cal.to_newtons(np.array([99]), np.zeros((1, 3)))
    assert cal.rows(np.array([10, 20, 99, 70000, -1])).tolist() == [0, 1, -1, -1, -1]


@pytest.mark.parametrize(
    ("text", "field"),
    [
        (GOOD.replace("id = 20", "id = 10"), r"cell\[1\]\.id: cell id 10 appears twice"),
        (GOOD.replace("id = 20", "id = 16383"), r"cell\[1\]\.id"),
        (GOOD.replace("id = 20", "id = 0"), r"cell\[1\]\.id"),
        (GOOD.replace("id = 20", 'id = "20"'), r"cell\[1\]\.id"),
        (
            GOOD.replace("force_gain = 3.0", "force_gain = 0.0"),
            r"cell\[1\]\.force_gain: gains must be > 0",
        ),
        (
            GOOD.replace("force_gain = 3.0", "force_gain = [1.0, 2.0]"),
            r"cell\[1\]\.force_gain: expected",
        ),
        (
            GOOD.replace("force_offset = [0.0, 0.5, 1.0]", 'force_offset = [0.0, "x", 1.0]'),
            r"cell\[1\]\.force_offset\[1\]",
        ),
        (
            GOOD.replace("position_mm = [15.0, 0.0, 0.0]", "position_mm = 15.0"),
            r"cell\[1\]\.position_mm",
        ),
        (GOOD.replace("position_mm = [15.0, 0.0, 0.0]", ""), r"cell\[1\]\.position_mm: missing"),
        (
            GOOD.replace(
                "position_mm = [15.0, 0.0, 0.0]", "position_mm = [15.0, 0.0, 0.0]\ngian = 2"
            ),
            r"cell\[1\]: unknown key\(s\) gian",
        ),
        (
            GOOD.replace("silence_timeout_s = 0.2", "silence_timeout_s = -1"),
            r"patch\.silence_timeout_s",
        ),
        (GOOD.replace("force_offset = 0.1", "force_offset = nan"), r"patch\.force_offset"),
        (GOOD.replace('name = "test-patch"', "name = 3"), r"patch\.name"),
        ("[patch]\nname = 'x'\n", r"cell: expected at least one \[\[cell\]\]"),
        (GOOD + "\n[extra]\n", r"unknown key\(s\) extra"),
        ("[patch\n", "invalid TOML"),
    ],
)
def test_errors_name_the_file_and_the_field(tmp_path, text, field):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match=field) as info:
        load_patch(path)
    assert str(path) in str(info.value)


def test_missing_and_binary_files(tmp_path):
    with pytest.raises(ConfigError, match=r"nope\.toml: cannot read patch file"):
        load_patch(tmp_path / "nope.toml")
    bad = tmp_path / "bin.toml"
    bad.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ConfigError, match="bin.toml: not UTF-8"):
        load_patch(bad)


def test_config_error_is_a_value_error():
    with pytest.raises(ValueError):
        PatchConfig.from_mapping({"cell": []}, "inline")
    assert isinstance(ForceCalibration((1,), np.zeros(3), np.ones(3)).index, np.ndarray)
