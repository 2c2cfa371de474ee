"""Every file aptkt writes appears whole or not at all (:func:`aptkt.files.replaced_atomically`):
an interrupted write leaves the old file and no temporary file; a finished one leaves the file
and nothing else."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from aptkt.errors import ConfigError, DatasetError, ModelFileError
from aptkt.experiments.run_store import RunStore
from aptkt.experiments.runs import RunSpec
from aptkt.experiments.tables import read_csv, write_csv
from aptkt.files import open_atomically, replaced_atomically
from aptkt.gp import LaplaceGPC
from aptkt.learning import LearnerConfig, Observations, PriorKnowledge
from aptkt.learning.feature_table import read_feature_table, write_feature_table


class Interrupted(Exception):
    pass


def names(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


@pytest.mark.parametrize("temp_suffix", [None, ".creating"], ids=["unique name", "side file"])
def test_an_interrupted_write_leaves_the_old_file_and_no_temporary_file(tmp_path, temp_suffix):
    path = tmp_path / "result.json"
    path.write_text("old")
    seen = []
    with pytest.raises(Interrupted):
        with replaced_atomically(path, ConfigError, temp_suffix=temp_suffix) as tmp:
            tmp.write_text("half of the new")
            seen.append(tmp)
            raise Interrupted
    assert seen[0].parent == tmp_path and seen[0] != path  # written beside it, not over it
    assert path.read_text() == "old"
    assert names(tmp_path) == ["result.json"]


def test_an_interrupted_write_through_a_handle_leaves_the_old_file(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("old")
    with pytest.raises(Interrupted):
        with open_atomically(path, ConfigError) as fh:
            fh.write("new")
            raise Interrupted
    assert path.read_text() == "old" and names(tmp_path) == ["t.csv"]


def test_a_finished_write_replaces_the_file_and_leaves_nothing_else(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("old")
    with open_atomically(path, ConfigError) as fh:
        fh.write("new")
    assert path.read_text() == "new" and names(tmp_path) == ["t.csv"]
    # The umask decides the mode, as for a file opened for writing.
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask


@pytest.mark.parametrize("temp_suffix", [None, ".creating"], ids=["unique name", "side file"])
def test_a_path_that_is_not_a_regular_file_is_never_replaced(tmp_path, temp_suffix):
    fifo = tmp_path / "out.csv"
    os.mkfifo(fifo)
    with pytest.raises(DatasetError, match="out.csv: is a FIFO"):
        with replaced_atomically(fifo, DatasetError, temp_suffix=temp_suffix) as tmp:
            tmp.write_text("x")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and names(tmp_path) == ["out.csv"]


def test_a_side_file_that_is_not_a_regular_file_is_refused(tmp_path):
    os.mkfifo(tmp_path / "d.h5.creating")
    with pytest.raises(DatasetError, match="d.h5.creating: is a FIFO"):
        with replaced_atomically(tmp_path / "d.h5", DatasetError, temp_suffix=".creating"):
            pass
    assert names(tmp_path) == ["d.h5.creating"]


def test_a_leftover_side_file_is_replaced(tmp_path):
    (tmp_path / "d.h5.creating").write_text("a killed write's")
    with replaced_atomically(tmp_path / "d.h5", DatasetError, temp_suffix=".creating") as tmp:
        assert not tmp.exists()
        tmp.write_text("new")
    assert names(tmp_path) == ["d.h5"] and (tmp_path / "d.h5").read_text() == "new"


# -- every writer -----------------------------------------------------------------------------
def _observations() -> Observations:
    rng = np.random.default_rng(0)
    objects = np.repeat(["a", "b"], 4)
    values = rng.normal(size=(8, 2)) + np.where(objects == "a", 0.0, 3.0)[:, None]
    return Observations("P", {"force": values}, objects, np.tile(np.arange(4), 2))


def _prior(path: Path) -> None:
    PriorKnowledge.build({"P": _observations()}).save(path)
    assert PriorKnowledge.load(path).objects == ["a", "b"]


def _model(path: Path) -> None:
    obs = _observations()
    LaplaceGPC(random_state=0).fit(obs.modalities["force"], obs.objects).save(path)
    assert LaplaceGPC.load(path).classes_.tolist() == ["a", "b"]


def _feature_table(path: Path) -> None:
    write_feature_table(path, {"P": _observations()})
    assert read_feature_table(path).object_names == ["a", "b"]


def _run_store(path: Path) -> None:
    spec = RunSpec("APTKT", LearnerConfig(), "d.h5", ("P",), ("a",), (0,), (1,))
    store = RunStore(path.parent)
    assert store.save(path.stem, spec, [{"step": 0}]) == path
    assert store.load(path.stem) == [{"step": 0}]


def _table(path: Path) -> None:
    write_csv(path, [{"x": 1}, {"y": 2}])
    assert read_csv(path) == [{"x": "1", "y": ""}, {"x": "", "y": "2"}]


@pytest.mark.parametrize(
    ("write", "name"),
    [
        (_prior, "prior.npz"),
        (_model, "model.npz"),
        (_feature_table, "table.csv"),
        (_feature_table, "table.h5"),
        (_run_store, "run.json"),
        (_table, "results.csv"),
    ],
    ids=["prior", "model", "feature table (CSV)", "feature table (HDF5)", "run store", "table"],
)
def test_each_writer_leaves_its_file_and_no_temporary_file(tmp_path, write, name):
    path = tmp_path / name
    path.write_text("an older version")
    write(path)
    assert names(tmp_path) == [name]


@pytest.mark.parametrize(
    ("write", "name"),
    [(_prior, "prior.npz"), (_model, "model.npz"), (_feature_table, "table.h5")],
    ids=["prior", "model", "feature table"],
)
def test_each_writer_interrupted_leaves_the_old_file(tmp_path, write, name, monkeypatch):
    path = tmp_path / name
    path.write_text("an older version")

    def interrupted_savez(file, *args, **kwargs):
        if hasattr(file, "write"):
            file.write(b"PK half an archive")
        else:  # (a writer that wrote in place)
            Path(file).write_bytes(b"PK half an archive")
        raise Interrupted

    def interrupted_hdf5(*args, **kwargs):
        raise Interrupted  # (the file has been created by then)

    monkeypatch.setattr(np, "savez_compressed", interrupted_savez)
    monkeypatch.setattr("h5py.File.create_dataset", interrupted_hdf5, raising=False)
    with pytest.raises(Interrupted):
        write(path)
    assert path.read_text() == "an older version" and names(tmp_path) == [name]


def test_a_model_saved_without_the_suffix_gets_it_as_numpy_gives_it(tmp_path):
    obs = _observations()
    LaplaceGPC(random_state=0).fit(obs.modalities["force"], obs.objects).save(tmp_path / "m")
    assert names(tmp_path) == ["m.npz"]


def test_a_model_file_that_is_a_fifo_is_refused(tmp_path):
    os.mkfifo(tmp_path / "m.npz")
    obs = _observations()
    model = LaplaceGPC(random_state=0).fit(obs.modalities["force"], obs.objects)
    with pytest.raises(ModelFileError, match="is a FIFO"):
        model.save(tmp_path / "m.npz")
