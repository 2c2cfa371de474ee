"""The HDF5 data set store: exact round trips, schema checks, features, crash safety under a
real SIGKILL, and bit-for-bit reproducible generation."""

from __future__ import annotations

import dataclasses
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from aptkt.actions import PAPER_ACTIONS
from aptkt.data import DatasetError, DatasetReader, DatasetWriter, repair, write_features
from aptkt.data.codec import raw_to_samples, samples_to_raw
from aptkt.runtime.generation import GenerationPlan, generate
from aptkt.sim import SimWorld
from aptkt.skin.protocol import RAW_FIELDS

FIELDS = ("cell_id", "t_ns", "proximity", "acc", "temp", "force")
PLAN = GenerationPlan(
    ("towel", "metal_toolbox"), (PAPER_ACTIONS["P1"], PAPER_ACTIONS["S2"]), repetitions=3, seed=2
)


def same_samples(a, b) -> bool:
    return all(np.array_equal(getattr(a.samples, f), getattr(b.samples, f)) for f in FIELDS)


def contents(path: Path) -> dict:
    """Every dataset and attribute of a file, for exact comparison."""
    out = {}
    with h5py.File(path, "r", swmr=True) as f:
        out["attrs"] = dict(f.attrs)

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out[name] = obj[...]

        f.visititems(visit)
    return out


def assert_same_contents(a: Path, b: Path) -> None:
    ca, cb = contents(a), contents(b)
    assert ca.keys() == cb.keys()
    for k in ca:
        if k == "attrs":
            assert ca[k] == cb[k]
        else:
            assert np.array_equal(ca[k], cb[k]), k


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    world = SimWorld(seed=2)
    return [world.explore("towel", "P1", 0), world.explore("metal_toolbox", "S2", 1)]


def test_round_trip_is_exact_and_compact(tmp_path, recordings):
    path = tmp_path / "d.h5"
    with DatasetWriter(path, description={"purpose": "test"}) as w:
        for r in recordings:
            w.append(r)
        with pytest.raises(DatasetError, match="already stored"):
            w.append(recordings[0])
    with DatasetReader(path) as rd:
        assert len(rd) == 2 and rd.keys() == [("towel", "P1", 0), ("metal_toolbox", "S2", 1)]
        assert rd.select(action="S2") == [1] and rd.description == {"purpose": "test"}
        for i, r in enumerate(recordings):
            back = rd.recording(i)
            assert same_samples(r, back)
            assert (back.start_ns, back.stop_ns, back.cells) == (r.start_ns, r.stop_ns, r.cells)
            assert back.metadata["calibration"] == r.metadata["calibration"]
        raw = rd.raw(0)
        assert raw["acc"].dtype == np.int16 and raw["force"].dtype == np.uint16
        info = rd.info()
    n = sum(len(r.samples) for r in recordings)
    assert info["samples"] == n and info["recordings"] == 2
    with h5py.File(path, "r", swmr=True) as f:
        stored = sum(d.id.get_storage_size() for d in f["recordings/samples"].values())
    assert (
        stored < 12 * n
    )  # raw integers, compressed: vs 28 bytes raw and 112 bytes of float64 per row


def test_values_off_the_wire_grid_are_refused(tmp_path, recordings):
    rec = recordings[0]
    bad = type(rec)(
        samples=type(rec.samples)(**{**rec.samples.as_dict(), "acc": rec.samples.acc + 1e-3}),
        start_ns=rec.start_ns,
        stop_ns=rec.stop_ns,
        cells=rec.cells,
        metadata=rec.metadata,
    )
    with DatasetWriter(tmp_path / "d.h5") as w, pytest.raises(ValueError, match="grid"):
        w.append(bad)


def test_schema_checks(tmp_path):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["schema"] = "something else"
    with pytest.raises(DatasetError, match="not an aptkt data set"):
        DatasetReader(other)
    newer = tmp_path / "newer.h5"
    DatasetWriter(newer).close()
    with h5py.File(newer, "a") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(DatasetError, match="schema version 99"):
        DatasetReader(newer)
    with pytest.raises(DatasetError, match="no such file"):
        DatasetReader(tmp_path / "missing.h5")
    with pytest.raises(DatasetError, match="exists"):
        DatasetWriter(newer)


def write_version_1(path: Path, recordings) -> None:
    """A data set as aptkt wrote it before schema version 2: metadata as variable-length
    strings, an index without metadata ranges (built by hand, as no writer makes it now)."""
    import json

    from aptkt.data.codec import samples_to_raw

    index_v1 = np.dtype(
        [
            ("object", "S64"),
            ("action", "S32"),
            ("trial", "<i4"),
            ("start_ns", "<i8"),
            ("stop_ns", "<i8"),
            ("row_start", "<i8"),
            ("row_stop", "<i8"),
        ]
    )
    rows, metas, raws, start = [], [], [], 0
    for r in recordings:
        meta = {**r.metadata, "cells": list(r.cells), "silent_cells": list(r.silent_cells)}
        raw = samples_to_raw(r.samples, meta)
        n = len(raw["cell_id"])
        rows.append(
            (
                meta["object"].encode(),
                meta["action"]["name"].encode(),
                meta["trial"],
                r.start_ns,
                r.stop_ns,
                start,
                start + n,
            )
        )
        metas.append(json.dumps(meta, sort_keys=True))
        raws.append(raw)
        start += n
    with h5py.File(path, "w") as f:
        f.attrs.update(
            schema="aptkt.dataset", schema_version=1, software_version="0.0.1", description="{}"
        )
        f["recordings/index"] = np.array(rows, dtype=index_v1)
        f.create_dataset("recordings/metadata", data=metas, dtype=h5py.string_dtype("utf-8"))
        for name in FIELDS:
            f[f"recordings/samples/{name}"] = np.concatenate([raw[name] for raw in raws])


def test_version_1_files_are_read_and_repair_rewrites_them_in_version_2(tmp_path, recordings):
    old = tmp_path / "v1.h5"
    write_version_1(old, recordings)
    with DatasetReader(old) as rd:
        assert rd.version == 1 and len(rd) == 2
        assert all(same_samples(rd.recording(i), recordings[i]) for i in range(2))
        assert rd.metadata(1)["object"] == recordings[1].metadata["object"]
    with pytest.raises(DatasetError, match="version 1 is read-only.*repair"):
        DatasetWriter(old, "a")
    assert repair(old) == 2
    with DatasetReader(old) as rd:
        assert rd.version == 2 and len(rd) == 2
        assert all(same_samples(rd.recording(i), recordings[i]) for i in range(2))
    with DatasetWriter(old, "a") as w:  # appendable now
        w.append(
            dataclasses.replace(recordings[0], metadata={**recordings[0].metadata, "trial": 7})
        )
    with DatasetReader(old) as rd:
        assert len(rd) == 3 and rd.key(2)[2] == 7


@pytest.mark.parametrize("tear", ["metadata past the end", "samples past the end", "empty row"])
def test_a_torn_last_append_is_left_out_and_nothing_before_it(tmp_path, recordings, tear):
    # What a writer killed mid-append can leave, since SWMR orders the writes of one dataset
    # but not those of different datasets: the new index row on disk before its data.
    path = tmp_path / "torn.h5"
    with DatasetWriter(path) as w:
        for r in recordings:
            w.append(r)
    with h5py.File(path, "a") as f:
        index = f["recordings/index"]
        row = index[1].copy()
        if tear == "metadata past the end":
            row["meta_start"], row["meta_stop"] = (
                f["recordings/metadata"].shape[0] + 4096,
                f["recordings/metadata"].shape[0] + 8192,
            )
        elif tear == "samples past the end":
            row["row_stop"] = f["recordings/samples/cell_id"].shape[0] + 1
        else:
            row = np.zeros((), dtype=index.dtype)
        index.resize(3, axis=0)
        index[2] = row
    with DatasetReader(path) as rd:
        assert len(rd) == 2 and rd.incomplete == 1
        assert all(same_samples(rd.recording(i), recordings[i]) for i in range(2))
    assert repair(path, backup=False) == 2


def test_features_are_stored_per_action(tmp_path, recordings):
    path = tmp_path / "d.h5"
    with DatasetWriter(path) as w:
        for r in recordings:
            w.append(r)
    values = np.arange(6.0).reshape(1, 6)
    write_features(path, "S2", "texture", [1], values)
    with DatasetReader(path) as rd:
        rows, got = rd.features("S2", "texture")
        assert rows.tolist() == [1] and np.array_equal(got, values)
        assert rd.feature_names() == {"S2": ["texture"]}
        with pytest.raises(KeyError):
            rd.features("P1", "force")
    with pytest.raises(ValueError, match="recording numbers"):
        write_features(path, "S2", "thermal", [5], values)


def _wait_for(path: Path, n: int, proc: subprocess.Popen, timeout: float = 120.0) -> int:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, "the writer finished before it could be killed"
        if path.exists():
            try:
                with DatasetReader(path) as rd:
                    if len(rd) >= n:
                        return len(rd)
            except (DatasetError, OSError, KeyError):
                pass  # the file is being created
        time.sleep(0.05)
    raise AssertionError("the writer made no progress")


def test_killed_generator_leaves_every_completed_trial_readable(tmp_path):
    path = tmp_path / "killed.h5"
    cmd = [
        sys.executable,
        "-m",
        "aptkt.cli",
        "dataset",
        "generate",
        "-o",
        str(path),
        "--objects",
        "towel,metal_toolbox",
        "--actions",
        "P1,S2",
        "-n",
        "3",
        "--seed",
        "2",
        "--no-progress",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        _wait_for(path, 3, proc)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    world = SimWorld(seed=2)
    with DatasetReader(path) as rd:
        n = len(rd)
        assert 3 <= n < len(PLAN)
        for i in range(n):  # every indexed trial is complete and exactly what the simulator makes
            obj, action, trial = rd.key(i)
            assert same_samples(rd.recording(i), world.explore(obj, action, trial))
    with pytest.raises(DatasetError, match="repair"):
        DatasetWriter(path, "a")
    # Resuming repairs the file and completes it: the same content as an uninterrupted run.
    info = generate(path, PLAN, resume=True, progress=False)
    assert info["repaired"] == n and info["recordings"] == len(PLAN)
    assert (tmp_path / "killed.h5.crashed").exists()
    clean = tmp_path / "clean.h5"
    generate(clean, PLAN, progress=False)
    assert_same_contents(path, clean)


WRITER = """
import sys, time
from aptkt.data import DatasetWriter, DatasetReader
src, dst = sys.argv[1], sys.argv[2]
with DatasetReader(src) as rd:
    recs = [rd.recording(i) for i in range(len(rd))]
w = DatasetWriter(dst)
k = 0
while True:  # append the same recordings under new trial numbers, as fast as possible
    for r in recs:
        r.metadata["trial"] = k
        w.append(r)
        k += 1
"""


def test_writer_killed_mid_write_leaves_a_valid_file(tmp_path, recordings):
    src = tmp_path / "src.h5"
    with DatasetWriter(src) as w:
        for r in recordings:
            w.append(r)
    rng = np.random.default_rng(0)
    for attempt in range(3):
        dst = tmp_path / f"hammer{attempt}.h5"
        proc = subprocess.Popen(
            [sys.executable, "-c", WRITER, str(src), str(dst)], stderr=subprocess.PIPE
        )
        try:
            _wait_for(dst, 4, proc)
            time.sleep(float(rng.uniform(0.0, 0.3)))
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
        with DatasetReader(dst) as rd:
            assert len(rd) >= 4
            for i in range(len(rd)):
                assert same_samples(rd.recording(i), recordings[i % 2])
        assert repair(dst, backup=False) >= 4


def test_same_seed_same_dataset_bit_for_bit(tmp_path):
    a, b, c = tmp_path / "a.h5", tmp_path / "b.h5", tmp_path / "c.h5"
    generate(a, PLAN, progress=False)
    generate(b, PLAN, progress=False, jobs=2)
    assert_same_contents(a, b)
    assert a.read_bytes() == b.read_bytes()
    other = GenerationPlan(PLAN.objects, PLAN.actions, PLAN.repetitions, seed=3)
    generate(c, other, progress=False)
    with DatasetReader(a) as ra, DatasetReader(c) as rc:
        assert not same_samples(ra.recording(0), rc.recording(0))


STARTER = """
import sys
from aptkt.data import DatasetWriter, DatasetReader
with DatasetReader(sys.argv[1]) as rd:
    rec = rd.recording(0)
for line in sys.stdin:  # a new file per line, written whole, then 'done' (or what went wrong)
    try:
        with DatasetWriter(line.strip()) as w:
            w.append(rec)
        print("done", flush=True)
    except Exception as exc:
        print(f"{type(exc).__name__}: {exc}".replace(chr(10), " "), flush=True)
"""


@pytest.mark.slow
def test_a_reader_polling_as_the_writer_starts_does_not_stop_it(tmp_path, recordings):
    # A reader opening the file takes its lock for a moment; the writer's switch to SWMR mode
    # used to fail then (errno 11) — in 3 of 60 starts with a reader polling like this one.
    # One writer process starts the 60 files in turn (its imports are no part of the race),
    # while this process opens the next file as fast as it can until it is written.
    src = tmp_path / "src.h5"
    with DatasetWriter(src) as w:
        w.append(recordings[0])
    proc = subprocess.Popen(
        [sys.executable, "-c", STARTER, str(src)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdin is not None and proc.stdout is not None
    try:
        for attempt in range(60):
            dst = tmp_path / f"started{attempt}.h5"
            proc.stdin.write(f"{dst}\n")
            proc.stdin.flush()
            while not select.select([proc.stdout], [], [], 0)[0]:
                try:
                    with DatasetReader(dst) as rd:
                        len(rd)
                except DatasetError:  # not created yet
                    pass
            answer = proc.stdout.readline().strip()
            assert answer == "done", f"start {attempt}: {answer or 'the writer process ended'}"
            with DatasetReader(dst) as rd:
                assert len(rd) == 1
    finally:
        proc.stdin.close()
        proc.wait(timeout=60)


def test_a_recording_off_the_wire_is_stored_from_its_own_integers(recordings):
    # Converted once: the source keeps the wire's integers with the samples, the store writes
    # them as they are, and reading converts them exactly as the source did.
    for rec in recordings:
        assert rec.samples.raw is not None
        stored = samples_to_raw(rec.samples, rec.metadata)
        for name in RAW_FIELDS:
            np.testing.assert_array_equal(stored[name], rec.samples.raw[name])
        back = raw_to_samples(stored, rec.metadata)
        for name in FIELDS:
            np.testing.assert_array_equal(getattr(back, name), getattr(rec.samples, name))
        # Samples without their integers (made by hand) take the checked way back to the grid.
        bare = dataclasses.replace(rec.samples, raw=None)
        again = samples_to_raw(bare, rec.metadata)
        for name in stored:
            np.testing.assert_array_equal(again[name], stored[name])
