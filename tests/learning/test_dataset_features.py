"""Stored features are a cache keyed by their extraction settings; reading never writes."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from aptkt.data import DatasetError, DatasetReader, DatasetWriter
from aptkt.learning.dataset import extract_features, load_observations, stale_features
from aptkt.learning.extract import ExtractionSettings
from aptkt.sim import SimWorld

ACTION = "P1"  # a press: every modality, thermal included


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("features") / "data.h5"
    world = SimWorld(seed=3)
    with DatasetWriter(path, "w") as w:
        for obj in ("towel", "metal_toolbox"):
            for trial in range(2):
                w.append(world.explore(obj, ACTION, trial))
    return path


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def same(a, b) -> None:
    assert set(a) == set(b)
    for name in a:
        assert list(a[name].objects) == list(b[name].objects)
        for m in a[name].modalities:
            np.testing.assert_array_equal(a[name].modalities[m], b[name].modalities[m])


def test_loading_reads_only_and_the_cache_is_keyed_by_the_settings(tmp_path, data):
    path = tmp_path / "data.h5"
    path.write_bytes(data.read_bytes())
    before = digest(path)
    in_memory = load_observations(path)
    assert digest(path) == before  # nothing was written into the file it reads
    with DatasetReader(path) as rd:
        assert rd.feature_names() == {}
    with pytest.raises(DatasetError, match="dataset features"):
        load_observations(path, extract_missing=False)

    assert stale_features(path, [ACTION]) == [ACTION]
    extract_features(path, progress=False)
    assert stale_features(path, [ACTION]) == []
    with DatasetReader(path) as rd:
        assert rd.feature_settings(ACTION) == ExtractionSettings().to_dict()
    same(load_observations(path, extract_missing=False), in_memory)

    # Other settings: the stored features are not theirs.
    coarse = ExtractionSettings(thermal_bin_s=0.2)
    assert stale_features(path, [ACTION], coarse) == [ACTION]
    with pytest.raises(DatasetError, match="extraction settings"):
        load_observations(path, settings=coarse, extract_missing=False)
    stored = digest(path)
    other = load_observations(path, settings=coarse)
    assert digest(path) == stored
    assert (
        other[ACTION].modalities["thermal"].shape[1]
        != in_memory[ACTION].modalities["thermal"].shape[1]
    )


def test_recordings_added_after_extraction_make_the_features_stale(tmp_path, data):
    """A data set completed after its features were stored (``dataset generate --resume``):
    the stored features miss the new recordings, so they are stale, and loading extracts
    rather than silently dropping the new recordings."""
    path = tmp_path / "data.h5"
    path.write_bytes(data.read_bytes())
    extract_features(path, progress=False)
    assert stale_features(path, [ACTION]) == []
    with DatasetWriter(path, "a") as w:
        w.append(SimWorld(seed=3).explore("towel", ACTION, 2))
    assert stale_features(path, [ACTION]) == [ACTION]
    with pytest.raises(DatasetError, match="every recording"):
        load_observations(path, extract_missing=False)
    table = load_observations(path)
    assert sorted(table[ACTION].trials[table[ACTION].objects == "towel"]) == [0, 1, 2]
    extract_features(path, progress=False)
    assert stale_features(path, [ACTION]) == []
    same(load_observations(path, extract_missing=False), table)


def test_filters_pick_the_same_rows_from_memory_and_from_the_file(tmp_path, data):
    path = tmp_path / "data.h5"
    path.write_bytes(data.read_bytes())
    subset = {"objects": ["towel"], "trials": [1]}
    in_memory = load_observations(path, **subset)
    extract_features(path, progress=False)
    stored = load_observations(path, extract_missing=False, **subset)
    same(in_memory, stored)
    assert list(stored[ACTION].objects) == ["towel"] and list(stored[ACTION].trials) == [1]


def test_a_filter_that_matches_nothing_gives_an_empty_table(data):
    table = load_observations(data, trials=[99])
    assert len(table[ACTION].objects) == 0
    assert {m: v.shape[0] for m, v in table[ACTION].modalities.items()} == {
        "force": 0,
        "thermal": 0,
    }


def test_features_extracted_in_worker_processes_are_the_same(tmp_path, monkeypatch):
    """Two actions, recordings in chunks that do not divide evenly (the chunk size made small),
    spread over two spawned processes in completion order: the stored values are those of the
    serial extraction, row for row."""
    from aptkt.experiments.executors import LocalExecutor
    from aptkt.learning import dataset

    world = SimWorld(seed=5)
    serial, parallel = tmp_path / "serial.h5", tmp_path / "parallel.h5"
    with DatasetWriter(serial, "w") as w:
        for obj in ("towel", "metal_toolbox", "cork_board"):
            for action in ("P1", "S2"):
                w.append(world.explore(obj, action, 0))
    parallel.write_bytes(serial.read_bytes())
    extract_features(serial, progress=False)
    monkeypatch.setattr(dataset, "_CHUNK_ROWS", 2)  # 3 recordings per action: chunks of 2, 1
    executor = LocalExecutor(2)
    try:
        counts = extract_features(parallel, progress=False, parallel_map=executor.imap_unordered)
    finally:
        executor.close()
    assert counts == {"P1": 3, "S2": 3}
    same(
        load_observations(parallel, extract_missing=False),
        load_observations(serial, extract_missing=False),
    )
