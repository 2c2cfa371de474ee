"""``aptkt dataset``: generate, info and repair from the command line."""

from __future__ import annotations

import json

import pytest

from aptkt.cli import main
from aptkt.data import DatasetReader


def test_generate_info_and_repair(tmp_path, capsys):
    out = tmp_path / "set.h5"
    args = [
        "dataset",
        "generate",
        "-o",
        str(out),
        "--objects",
        "towel,cork_board",
        "--actions",
        "P1",
        "-n",
        "2",
        "--seed",
        "4",
        "--no-progress",
        "--json",
    ]
    assert main(args) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["recordings"] == 4 and info["objects"] == {"towel": 2, "cork_board": 2}
    assert info["wall_seconds"] > 0 and info["file_bytes"] > 0
    assert main(["dataset", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "4 recordings" in text and "cork_board" in text and "seed 4" in text
    assert (
        main(
            [
                "dataset",
                "generate",
                "-o",
                str(out),
                "--objects",
                "towel",
                "--actions",
                "P1",
                "-n",
                "1",
                "--no-progress",
            ]
        )
        == 1
    )
    assert "exists" in capsys.readouterr().err
    assert main(["dataset", "repair", str(out)]) == 0
    with DatasetReader(out) as rd:
        assert len(rd) == 4


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--objects", "teapot"], "unknown object"),
        (["--actions", "P9"], "unknown action"),
        (["-n", "0"], "repetitions"),
    ],
)
def test_bad_arguments_are_clear_errors(tmp_path, capsys, extra, message):
    assert main(["dataset", "generate", "-o", str(tmp_path / "x.h5"), "--no-progress", *extra]) == 1
    assert message in capsys.readouterr().err


def test_custom_objects_and_actions_files(tmp_path, capsys):
    objects = tmp_path / "objs.toml"
    objects.write_text("""
[[object]]
name = "felt_pad"
  [[object.layer]]
  thickness = 0.004
  modulus = 6e4
  conductivity = 0.05
  heat_capacity = 2e5
  [object.surface]
  friction_static = 0.8
  friction_kinetic = 0.7
  roughness_rms = 2e-5
  contact_conductance = 1200
""")
    actions = tmp_path / "acts.toml"
    actions.write_text("""
[[action]]
name = "P3"
movement = "press"
depth = 0.0015
hold_time = 1.0
""")
    out = tmp_path / "custom.h5"
    assert (
        main(
            [
                "dataset",
                "generate",
                "-o",
                str(out),
                "--objects-file",
                str(objects),
                "--objects",
                "felt_pad",
                "--actions-file",
                str(actions),
                "-n",
                "1",
                "--no-progress",
            ]
        )
        == 0
    )
    with DatasetReader(out) as rd:
        rec = rd.recording(0)
        assert rd.keys() == [("felt_pad", "P3", 0)]
    assert rec.metadata["object"] == "felt_pad" and rec.metadata["action"]["depth"] == 0.0015
    assert rec.duration == pytest.approx(1.0, abs=0.01)
