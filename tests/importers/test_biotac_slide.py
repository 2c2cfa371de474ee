"""The BioTac sliding set's importer, on a synthetic set in its raw format."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest
from antropy import hjorth_params
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from aptkt.cli import main
from aptkt.errors import RawDataError
from aptkt.importers.biotac_slide import (
    COLUMNS,
    MAX_TRIAL_BYTES,
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


# -- files that are not trials, values no sensor gives, trials given twice -----------------------
def _import_line(tmp_path, root, capsys) -> str:
    """``aptkt dataset import`` of ``root``: exit code 1, one error line (returned), no table."""
    out = tmp_path / "out.csv"
    argv = ["dataset", "import", "biotac-slide", str(root), "-o", str(out), "--no-progress"]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert not out.exists()
    return err


def _in_thread(fn, seconds=20.0):
    """``fn()``'s exception, or None; an AssertionError if it is still running after
    ``seconds`` (a read that blocks, or never ends)."""
    outcome: list[BaseException | None] = []

    def run():
        try:
            fn()
            outcome.append(None)
        except BaseException as exc:  # noqa: BLE001 - the test inspects it
            outcome.append(exc)

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(seconds)
    assert not worker.is_alive(), "the import did not end"
    return outcome[0]


@pytest.mark.parametrize("kind", ["dev-zero", "fifo", "huge", "one-long-line"])
def test_only_regular_trial_files_of_bounded_size_are_read(tmp_path, capsys, kind):
    # The report: a trial file that is a link to /dev/zero read until memory ran out, a FIFO
    # hung, a 300 MB single-line file ended in a MemoryError traceback.
    root = write_raw_set(tmp_path / "set", materials=2, trials=2)
    trial = root / "raw_data" / "mat2" / "mat2_3_bio.csv"
    if kind == "dev-zero":
        trial.symlink_to("/dev/zero")
        expected = "is a character device, not a regular file"
    elif kind == "fifo":
        os.mkfifo(trial)
        expected = "is a FIFO (named pipe), not a regular file"
    elif kind == "huge":
        with trial.open("wb") as fh:  # sparse: 300 MB of one line, on no disk space
            fh.truncate(300 << 20)
        expected = f"{300 << 20} bytes, more than the {MAX_TRIAL_BYTES} bytes"
    else:
        trial.write_bytes(b"1," * (1 << 20))
        expected = "line 1: longer than"
    err = _in_thread(lambda: import_biotac_slide(root))
    assert isinstance(err, RawDataError) and str(trial) in str(err) and expected in str(err)
    line = _in_thread(lambda: _import_line(tmp_path, root, capsys))
    assert line is None


@pytest.mark.parametrize("value", ["1e160", "-1e160", "1.7e308"])
def test_a_value_no_biotac_gives_is_named_by_line_and_column(tmp_path, capsys, value):
    # The report: a pressure of ±1e160 ended in a traceback ("non-finite value inf").
    root = write_raw_set(tmp_path / "set", materials=2, trials=2)
    path = _broken(
        root,
        lambda ls: (
            ls[:6] + [",".join([*ls[6].split(",")[:3], value, *ls[6].split(",")[4:]])] + ls[7:]
        ),
    )
    with pytest.raises(RawDataError, match=r"line 7, column pdc: .* is beyond ±1e\+100") as err:
        import_biotac_slide(root)
    assert str(path) in str(err.value)
    assert "line 7, column pdc" in _import_line(tmp_path, root, capsys)


@settings(max_examples=40, deadline=None)
@given(
    cells=st.lists(
        st.tuples(
            st.integers(1, 79),
            st.integers(1, len(COLUMNS) - 1),
            st.floats(allow_nan=False, allow_infinity=False, width=64),
        ),
        min_size=1,
        max_size=6,
    )
)
def test_any_finite_values_give_finite_features_or_one_error(tmp_path_factory, cells):
    frames = trial_frames(1, 1)
    for row, column, value in cells:
        frames[row, column] = value
    root = tmp_path_factory.mktemp("values")
    write_trial(root / "raw_data" / "mat1" / "mat1_1_bio.csv", frames)
    write_trial(root / "raw_data" / "mat2" / "mat2_1_bio.csv", trial_frames(2, 1))
    try:
        obs = import_biotac_slide(root)
    except RawDataError:
        return
    for values in obs.modalities.values():
        assert np.all(np.isfinite(values))


def test_a_trial_given_twice_is_refused_naming_both_files(tmp_path, capsys):
    # The report: mat1_01_bio.csv beside mat1_1_bio.csv made two rows mat1,slide,1, which
    # `benchmark` later refused.
    root = write_raw_set(tmp_path / "set", materials=2, trials=2)
    twin = root / "raw_data" / "mat1" / "mat1_01_bio.csv"
    twin.write_bytes((root / "raw_data" / "mat1" / "mat1_1_bio.csv").read_bytes())
    with pytest.raises(RawDataError, match="both trial 1 of mat1") as err:
        find_trials(root)
    assert "mat1_01_bio.csv" in str(err.value) and "mat1_1_bio.csv" in str(err.value)
    assert "both trial 1 of mat1" in _import_line(tmp_path, root, capsys)


def test_a_trial_number_beyond_an_integer_is_one_error_line(tmp_path, capsys):
    # (Found by a sweep: mat1_<30 nines>_bio.csv ended in an OverflowError traceback.)
    root = write_raw_set(tmp_path / "set", materials=2, trials=2)
    src = root / "raw_data" / "mat1" / "mat1_1_bio.csv"
    (src.parent / ("mat1_" + "9" * 30 + "_bio.csv")).write_bytes(src.read_bytes())
    with pytest.raises(RawDataError, match="trial number 9+ is beyond 999999999"):
        find_trials(root)
    assert "is beyond 999999999" in _import_line(tmp_path, root, capsys)
