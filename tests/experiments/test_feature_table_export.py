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


def _texture_transform(prior_file):
    from aptkt.learning import PriorKnowledge

    prior = PriorKnowledge.load(prior_file)
    return {a: ap.pipeline.transforms.get("texture") for a, ap in prior.actions.items()}


@pytest.mark.parametrize("suffix", [".csv", ".h5"])
def test_an_exported_table_says_it_holds_this_skins_features(quick_data, tmp_path, suffix):
    from aptkt.learning.pipeline import SKIN_EXTRACTION

    table = tmp_path / f"features{suffix}"
    assert main(["dataset", "export-features", str(quick_data), "-o", str(table)]) == 0
    assert read_feature_table(table).extraction == SKIN_EXTRACTION


@pytest.fixture(scope="module")
def exported(quick_data, tmp_path_factory):
    table = tmp_path_factory.mktemp("exported") / "features.csv"
    assert main(["dataset", "export-features", str(quick_data), "-o", str(table)]) == 0
    return table


@pytest.fixture(scope="module")
def data_set_logs(quick_data, tmp_path_factory):
    """The log columns of each action's texture in the data set's own prior of PRIORS."""
    built = tmp_path_factory.mktemp("prior") / "from-data-set.npz"
    assert main(["prior", "build", str(quick_data), "-o", str(built), "--objects", PRIORS]) == 0
    return {a: t.log_columns if t is not None else () for a, t in _texture_transform(built).items()}


@pytest.mark.parametrize(
    ("asked", "skin"), [(None, True), ("aptkt-skin", True), ("other", False), ("auto", True)]
)
def test_learning_from_an_exported_table_transforms_as_from_the_data_set(
    exported, data_set_logs, tmp_path, capsys, asked, skin
):
    """The exported table's marker gives it this skin's transforms (log of the texture's
    activities), as the data set's own prior has; --extraction other z-scores every column."""
    out = tmp_path / "learned"
    args = ["learn", "--table", str(exported), "--prior-objects", PRIORS, "--objects", NEW]
    args += ["--test-trials", "3:6", "--budget", "0", "--runs", "1", "-o", str(out)]
    args += [] if asked is None else ["--extraction", asked]
    assert main(args) == 0
    logs = {
        a: t.log_columns if t is not None else ()
        for a, t in _texture_transform(out / "prior.npz").items()
    }
    assert (0, 1, 2) in data_set_logs.values()  # the sliding actions' texture
    want = {a: data_set_logs[a] for a in logs}
    assert logs == (want if skin else dict.fromkeys(want, ()))


def test_an_unmarked_table_of_the_same_features_gets_no_skin_transform(quick_data, tmp_path):
    """Another sensor's table with groups called texture and thermal: z-scored as they are,
    unless asked for this skin's transforms."""
    from aptkt.learning.feature_table import write_feature_table

    unmarked = tmp_path / "unmarked.csv"
    observations = load_observations(quick_data)
    for obs in observations.values():  # as another program would have computed them
        obs.extraction = None
    write_feature_table(unmarked, observations)
    assert read_feature_table(unmarked).extraction is None
    for asked, logs in (("auto", ()), ("aptkt-skin", (0, 1, 2))):
        out = tmp_path / f"prior-{asked}.npz"
        args = ["prior", "build", str(unmarked), "-o", str(out), "--objects", PRIORS]
        assert main([*args, "--extraction", asked]) == 0
        got = {t.log_columns if t is not None else () for t in _texture_transform(out).values()}
        assert logs in got and got <= {logs, ()}


def test_extraction_mistakes_are_one_line(quick_data, tmp_path, capsys):
    out = tmp_path / "p.npz"
    assert main(["prior", "build", str(quick_data), "-o", str(out), "--extraction", "other"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("aptkt prior build: error: --extraction: only for a feature table")
    assert "\n" not in err
    args = ["learn", "--robot", "sim", "--prior", str(out), "--objects", NEW]
    args += ["--extraction", "other", "-o", str(tmp_path / "x")]
    assert main(args) == 1
    err = capsys.readouterr().err.strip()
    assert err == "aptkt learn: error: --extraction: only when learning from a table (learn TABLE)"
