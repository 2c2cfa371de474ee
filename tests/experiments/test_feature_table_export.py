"""``aptkt dataset export-features`` then ``aptkt learn --table``: the worked example of
docs/feature-tables.md on the quick simulated data set."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.learning.dataset import load_observations
from aptkt.learning.feature_table import read_feature_table

PRIORS = "rough_sponge,paper_box,metal_toolbox"
NEW = "smooth_sponge,hard_box,biscuit_box"


@pytest.mark.parametrize("suffix", [".csv", ".h5"])
def test_export_holds_every_stored_observation(quick_data, tmp_path, capsys, suffix):
    out = tmp_path / f"features{suffix}"
    assert main(["dataset", "export-features", str(quick_data), "-o", str(out)]) == 0
    assert f"{out}: " in capsys.readouterr().out
    table = read_feature_table(out).observations()
    stored = load_observations(quick_data)
    assert sorted(table) == sorted(stored)
    for action, obs in stored.items():
        got = table[action]
        order = np.lexsort((got.trials, got.objects))
        want = np.lexsort((obs.trials, obs.objects))
        np.testing.assert_array_equal(got.objects[order], obs.objects[want])
        np.testing.assert_array_equal(got.trials[order], obs.trials[want])
        for m in obs.modality_names:
            np.testing.assert_array_equal(got.modalities[m][order], obs.modalities[m][want])


def test_export_then_learn(quick_data, tmp_path, capsys):
    table = tmp_path / "features.csv"
    assert main(["dataset", "export-features", str(quick_data), "-o", str(table)]) == 0
    out = tmp_path / "learned"
    args = ["learn", "--table", str(table), "--prior-objects", PRIORS, "--objects", NEW]
    args += ["--test-trials", "3:6", "--budget", "2", "--runs", "1", "-o", str(out)]
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["actions"] == ["P2", "S4", "C1"] or sorted(summary["actions"]) == [
        "C1",
        "P2",
        "S4",
    ]
    assert set(summary["final_mean_accuracy"]) == {"APTKT", "APTKT+aux", "baseline"}


def test_export_errors_are_one_line(quick_data, tmp_path, capsys):
    out = tmp_path / "t.csv"
    assert (
        main(["dataset", "export-features", str(quick_data), "-o", str(out), "--actions", "P9"])
        == 1
    )
    err = capsys.readouterr().err.strip()
    assert (
        err.startswith("aptkt dataset export-features: error:") and "P9" in err and "\n" not in err
    )
    assert main(["dataset", "export-features", str(quick_data), "-o", str(tmp_path / "t.txt")]) == 1
    assert ".csv or an HDF5" in capsys.readouterr().err
