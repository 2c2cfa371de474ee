"""The BioTac sliding set's importer, on a synthetic set in its raw format."""

from __future__ import annotations

import numpy as np
import pytest
from antropy import hjorth_params
from scipy import stats

from aptkt.cli import main
from aptkt.errors import RawDataError
from aptkt.importers.biotac_slide import (
    MODALITIES,
    find_trials,
    import_biotac_slide,
    trial_features,
)
from aptkt.learning.feature_table import read_feature_table

from .raw_biotac import trial_frames, write_raw_set, write_trial


def test_every_trial_becomes_one_row_with_the_four_modalities(tmp_path):
    root = write_raw_set(tmp_path / "set", materials=3, trials=4)
    obs = import_biotac_slide(root)
    assert obs.action == "slide" and len(obs) == 12
    assert obs.object_names == ["mat1", "mat2", "mat3"]
    assert obs.trials.tolist() == [1, 2, 3, 4] * 3
    assert {m: v.shape[1] for m, v in obs.modalities.items()} == MODALITIES
    # The repository's root and its raw_data folder are both accepted.
    again = import_biotac_slide(root / "raw_data")
    for m in MODALITIES:
        np.testing.assert_array_equal(again.modalities[m], obs.modalities[m])


def test_features_against_independent_computations():
    """Hjorth parameters against antropy (activity: numpy's variance), the slope against
    scipy's linear regression, the rest against numpy."""
    frames = trial_frames(2, 5)
    got = trial_features(frames)
    pac = frames[:, 4:26].reshape(-1)
    mobility, complexity = hjorth_params(pac)
    np.testing.assert_allclose(
        got["vibration"], [np.log10(np.var(pac)), mobility, complexity], rtol=1e-9
    )
    np.testing.assert_allclose(got["pressure"], [frames[:, 3].mean(), frames[:, 3].std()])
    slope = stats.linregress(frames[:, 0] - frames[0, 0], frames[:, 1]).slope
    np.testing.assert_allclose(
        got["temperature"], [frames[:, 1].mean(), slope, frames[:, 2].mean()], rtol=1e-9
    )
    np.testing.assert_allclose(got["electrodes"], frames[:, 26:].mean(axis=0))


def test_materials_and_modalities_can_be_chosen(tmp_path):
    root = write_raw_set(tmp_path / "set", materials=4, trials=2)
    obs = import_biotac_slide(root, materials=["mat4", "mat2"], modalities=["pressure"])
    assert obs.object_names == ["mat2", "mat4"] and list(obs.modalities) == ["pressure"]
    with pytest.raises(RawDataError, match="no trials of mat9"):
        import_biotac_slide(root, materials=["mat9"])
    with pytest.raises(RawDataError, match="unknown modalities texture"):
        import_biotac_slide(root, modalities=["texture"])


def _broken(tmp_path, edit):
    path = write_trial(tmp_path / "raw_data" / "mat1" / "mat1_1_bio.csv", trial_frames(1, 1))
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n")
    return path


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda ls: ["time,tdc"] + ls[1:], "line 1: not a BioTac frame header"),
        (lambda ls: ls[:5] + [ls[5].replace(",", ",x,", 1)] + ls[6:], "line 6: 46 values"),
        (lambda ls: ls[:5] + [ls[5].replace(",", ",nan_,", 1)[: -len(",")]] + ls[6:], "line 6"),
        # Line 8 jumps ahead: line 9 is the first whose timestamp does not increase.
        (lambda ls: ls[:7] + ["1e18," + ls[7].split(",", 1)[1]] + ls[8:], "line 9"),
        (lambda ls: ls[:20], "19 frames; a slide needs at least 50"),
        (
            lambda ls: (
                ls[:3] + [",".join([ls[3].split(",")[0], "inf", *ls[3].split(",")[2:]])] + ls[4:]
            ),
            "line 4: a value is not finite",
        ),
        (lambda ls: [], "the file is empty"),
    ],
)
def test_a_damaged_trial_is_named_by_file_and_line(tmp_path, edit, message):
    path = _broken(tmp_path, edit)
    with pytest.raises(RawDataError, match=message) as err:
        import_biotac_slide(tmp_path)
    assert str(path) in str(err.value)


def test_a_constant_vibration_is_refused():
    frames = trial_frames(1, 1)
    frames[:, 4:26] = 7.0
    with pytest.raises(RawDataError, match="constant"):
        trial_features(frames)


def test_no_trials_and_no_directory_are_errors(tmp_path):
    with pytest.raises(RawDataError, match="no such directory"):
        find_trials(tmp_path / "nothing")
    (tmp_path / "raw_data" / "mat1").mkdir(parents=True)
    (tmp_path / "raw_data" / "mat1" / "mat1_1_cw.csv").write_text("x")
    with pytest.raises(RawDataError, match="no BioTac trials"):
        find_trials(tmp_path)


@pytest.mark.parametrize("suffix", [".csv", ".h5"])
def test_the_command_writes_a_feature_table_and_never_overwrites_unasked(tmp_path, capsys, suffix):
    root = write_raw_set(tmp_path / "set", materials=3, trials=4)
    out = tmp_path / f"t{suffix}"
    argv = ["dataset", "import", "biotac-slide", str(root), "-o", str(out), "--no-progress"]
    assert main(argv) == 0
    assert "12 rows, action slide, 3 materials" in capsys.readouterr().out
    table = read_feature_table(out)
    obs = table.observations()["slide"]
    direct = import_biotac_slide(root)
    for m in MODALITIES:
        np.testing.assert_allclose(obs.modalities[m], direct.modalities[m], rtol=1e-15)
    before = out.read_bytes()
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert (
        err.count("\n") == 0 and err.startswith("aptkt dataset import: error:") and "--force" in err
    )
    assert out.read_bytes() == before
    assert main([*argv, "--force", "--modalities", "pressure,temperature"]) == 0
    assert read_feature_table(out).columns[0].startswith("pressure")


def test_command_mistakes_are_one_line_and_write_nothing(tmp_path, capsys):
    root = write_raw_set(tmp_path / "set", materials=2, trials=2)
    _broken(root, lambda ls: ls[:10])
    for argv, fragment in (
        (
            ["dataset", "import", "biotac-slide", str(root), "-o", str(tmp_path / "a.csv")],
            "9 frames",
        ),
        (
            [
                "dataset",
                "import",
                "biotac-slide",
                str(tmp_path / "no"),
                "-o",
                str(tmp_path / "b.csv"),
            ],
            "no such directory",
        ),
        (
            ["dataset", "import", "biotac-slide", str(root), "-o", str(tmp_path / "c.txt")],
            ".csv or an HDF5",
        ),
    ):
        assert main(argv) == 1
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and err.startswith("aptkt dataset import: error:"), err
        assert fragment in err, err
    assert not list(tmp_path.glob("*.csv")) and not list(tmp_path.glob("*.txt"))
