"""A saved model is read as a prior file is: only its own members, their declared sizes
checked before anything is decompressed, every member checked before the model is rebuilt;
any problem is a ModelFileError naming the file and the member."""

from __future__ import annotations

import json
import os
import threading
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from npz_files import npy_header, opened_members

from aptkt.errors import ModelFileError
from aptkt.files import NPZ_MAX_BYTES
from aptkt.gp import LaplaceGPC, TransferSource

from .conftest import make_blobs


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    X, y = make_blobs(6, 3, 2, seed=3)
    source = make_blobs(4, 2, 2, seed=4)[0]
    labels = np.r_[np.ones(4), -np.ones(4)]
    model = LaplaceGPC(random_state=0).fit(
        X, y, sources={1: [TransferSource(source, labels, 0.6, name="s")]}
    )
    path = tmp_path_factory.mktemp("model") / "model.npz"
    model.save(path)
    return path


def _members(path):
    with np.load(path, allow_pickle=False) as d:
        return {k: d[k] for k in d.files}


def _with_member(src, dst, member, data):
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as b:
        for item in a.infolist():
            if item.filename != member + ".npy":
                b.writestr(item, a.read(item))
        b.writestr(member + ".npy", data)
    return dst


def test_the_saved_model_loads(saved):
    model = LaplaceGPC.load(saved)
    assert model.classes_.tolist() == [0, 1, 2]
    assert model.sources_[1][0].name == "s"


@pytest.mark.parametrize("member", ["X", "zeros"])
def test_declared_sizes_are_checked_before_anything_is_read(saved, tmp_path, monkeypatch, member):
    # The report: a 4 MB file whose extra member held 4 GiB of zeros, or one declaring 10**11
    # floats, ended in "MemoryError: Unable to allocate".
    bad = _with_member(saved, tmp_path / "huge.npz", member, npy_header((10**11,)))
    assert 10**11 * 8 > NPZ_MAX_BYTES
    read = []
    original = np.lib.format.read_array
    monkeypatch.setattr(
        np.lib.format, "read_array", lambda *a, **k: read.append(1) or original(*a, **k)
    )
    with pytest.raises(ModelFileError, match=f"{bad}: member '{member}"):
        LaplaceGPC.load(bad)
    assert read == []


def test_an_extra_member_is_never_opened(saved, tmp_path, monkeypatch):
    bad = _with_member(saved, tmp_path / "zeros.npz", "zeros", npy_header((2**29,)))
    opened = opened_members(monkeypatch)
    with pytest.raises(ModelFileError, match="'zeros.npy' is not part of a saved LaplaceGPC"):
        LaplaceGPC.load(bad)
    assert "zeros.npy" not in opened


def test_a_model_too_large_to_rebuild_is_refused_before_allocating(saved, tmp_path):
    # 10^5 rows declare 1.6 MB, within the cap; their kernel matrices would need 720 GB.
    members = _members(saved)
    del members["source_X_0"], members["source_y_0"]
    meta = _meta(members)
    meta["sources"] = []
    members.update(meta=_json(meta), X=np.zeros((100_000, 2)), y=np.arange(100_000) % 3)
    np.savez(tmp_path / "m.npz", **members)
    with pytest.raises(ModelFileError, match="member 'X': the model cannot be rebuilt"):
        LaplaceGPC.load(tmp_path / "m.npz")


@pytest.mark.parametrize("member", ["X", "y", "theta", "meta", "source_X_0", "source_y_0"])
def test_a_missing_member_is_named(saved, tmp_path, member):
    # The report: a model file without X raised a bare KeyError: 'X'.
    members = _members(saved)
    del members[member]
    np.savez(tmp_path / "m.npz", **members)
    with pytest.raises(ModelFileError, match=f"member '{member}'"):
        LaplaceGPC.load(tmp_path / "m.npz")


def _meta(members):
    return json.loads(members["meta"].tobytes())


def _json(value):
    return np.frombuffer(json.dumps(value).encode(), dtype=np.uint8)


CORRUPTIONS = {
    "y out of range": ("y", lambda m: {**m, "y": m["y"] + 5}),
    "y of other length": ("y", lambda m: {**m, "y": m["y"][:-1]}),
    "y of floats": ("y", lambda m: {**m, "y": m["y"].astype(float)}),
    "X with NaN": ("X", lambda m: {**m, "X": np.where(m["X"] > 0, np.nan, m["X"])}),
    "X as text": ("X", lambda m: {**m, "X": m["X"].astype(str)}),
    "theta rows": ("theta", lambda m: {**m, "theta": m["theta"][:1]}),
    "theta columns": ("meta|theta|X", lambda m: {**m, "theta": m["theta"][:, :1]}),
    "meta not JSON": ("meta", lambda m: {**m, "meta": np.frombuffer(b"{nope", np.uint8)}),
    "meta nested": ("meta", lambda m: {**m, "meta": np.frombuffer(b"[" * 100_000, np.uint8)}),
    "meta a list": ("meta", lambda m: {**m, "meta": _json([1])}),
    "meta format": ("meta", lambda m: {**m, "meta": _json({**_meta(m), "format": "x"})}),
    "unknown parameter": (
        "meta",
        lambda m: {**m, "meta": _json({**_meta(m), "params": {"bogus": 1}})},
    ),
    "one class": ("meta", lambda m: {**m, "meta": _json({**_meta(m), "classes": [0]})}),
    "source of no class": (
        "meta",
        lambda m: {
            **m,
            "meta": _json({**_meta(m), "sources": [{**_meta(m)["sources"][0], "class": 9}]}),
        },
    ),
    "source columns": ("source_X_0", lambda m: {**m, "source_X_0": m["source_X_0"][:, :1]}),
    "source labels": ("source_X_0", lambda m: {**m, "source_y_0": m["source_y_0"][:2]}),
    "source lambda": (
        "source_X_0",
        lambda m: {
            **m,
            "meta": _json(
                {**_meta(m), "sources": [{**_meta(m)["sources"][0], "transfer_lambda": 7}]}
            ),
        },
    ),
    "a source too many": (
        "source_X_1",
        lambda m: {
            **m,
            "meta": _json({**_meta(m), "sources": _meta(m)["sources"] * 2}),
        },
    ),
    "a stray source": ("source_X_3", lambda m: {**m, "source_X_3": m["source_X_0"]}),
}


@pytest.mark.parametrize("name", CORRUPTIONS)
def test_corrupt_members_are_named(saved, tmp_path, name):
    member, corrupt = CORRUPTIONS[name]
    np.savez(tmp_path / "m.npz", **corrupt(_members(saved)))
    with pytest.raises(ModelFileError, match=rf"m\.npz: .*({member})"):
        LaplaceGPC.load(tmp_path / "m.npz")


ARRAYS = st.sampled_from(
    [
        np.zeros(0),
        np.zeros((2, 2)),
        np.arange(3),
        np.array([np.inf]),
        np.array(["a", "b"]),
        np.array([True, False]),
        np.frombuffer(b'{"format": "aptkt.LaplaceGPC/2"}', np.uint8),
        np.float64(0.5),
        np.full((40, 2), -1),
    ]
)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    drop=st.lists(st.sampled_from(["X", "y", "theta", "meta", "source_X_0", "source_y_0"])),
    replace=st.dictionaries(
        st.sampled_from(["X", "y", "theta", "meta", "source_X_0", "source_y_0"]), ARRAYS
    ),
)
def test_any_damage_is_a_model_file_error_or_a_model(saved, tmp_path, drop, replace):
    members = {k: v for k, v in _members(saved).items() if k not in drop}
    members.update(replace)
    path = tmp_path / "m.npz"
    np.savez(path, **members)
    try:
        LaplaceGPC.load(path)
    except ModelFileError as exc:
        assert str(path) in str(exc)


@pytest.mark.parametrize("kind", ["fifo", "directory", "device"])
def test_only_a_regular_file_is_read(tmp_path, kind):
    # A FIFO used to block the load for ever (zipfile opens it and waits for a writer).
    path = tmp_path / "m.npz"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    else:
        path.symlink_to(os.devnull)
    outcome: list[BaseException] = []
    worker = threading.Thread(
        target=lambda: _catch(outcome, lambda: LaplaceGPC.load(path)), daemon=True
    )
    worker.start()
    worker.join(10.0)
    assert not worker.is_alive(), "load blocked"
    assert isinstance(outcome[0], ModelFileError) and "not a regular file" in str(outcome[0])


def _catch(into, fn):
    try:
        fn()
    except BaseException as exc:  # noqa: BLE001 - the test inspects it
        into.append(exc)
