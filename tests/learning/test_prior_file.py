"""A prior-knowledge file is checked member by member before anything is built from it:
corrupt, inconsistent, foreign or oversized files are a PriorFileError naming the member."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
from npz_files import npy_header, opened_members

from aptkt.cli import main
from aptkt.errors import PriorFileError
from aptkt.learning import PriorKnowledge
from aptkt.learning.prior_file import PRIOR_FILE_MAX_BYTES

from .synthetic import draw, make_world


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    priors, _, means = make_world(n_prior=3)
    path = tmp_path_factory.mktemp("prior") / "good.npz"
    PriorKnowledge.build(draw(means, priors, 4, seed=1), seed=0).save(path)
    return path


def _members(path):
    with np.load(path, allow_pickle=False) as d:
        return {k: d[k] for k in d.files}


def _write(path, members):
    np.savez(path, **members)
    return path


def _meta(members):
    return json.loads(members["meta"].tobytes())


def _set_meta(members, meta):
    members["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)


def test_the_saved_file_loads_and_round_trips(good):
    prior = PriorKnowledge.load(good)
    assert prior.objects == ["old0", "old1", "old2"]
    assert set(prior.actions) == {"P1", "S1"}


def _corrupt_pipeline_shape(m):
    key = "a0/pipeline/thermal/mean"
    m[key] = np.concatenate([m[key], [0.0]])
    return key


def _integer_object_names(m):
    m["a0/obs/objects"] = np.arange(len(m["a0/obs/objects"]))
    return "a0/obs/objects"


def _actions_as_a_string(m):
    meta = _meta(m)
    meta["actions"] = "P1S1"
    _set_meta(m, meta)
    return "meta"


def _missing_member(m):
    del m["a1/model/theta"]
    return "a1/model/theta"


def _labels_differ(m):
    m["a0/model/y"] = m["a0/model/y"][::-1].copy()
    return "a0/model/y"


def _model_features_wrong_width(m):
    m["a1/model/X"] = m["a1/model/X"][:, :-1].copy()
    return "a1/model/X"


def _non_finite(m):
    m["a0/obs/modality/force"] = m["a0/obs/modality/force"].copy()
    m["a0/obs/modality/force"][0, 0] = np.nan
    return "a0/obs/modality/force"


def _huge_feature(m):
    # Finite, so it loaded; refitting it (a merge) squared it into infinity.
    m["a0/obs/modality/force"] = m["a0/obs/modality/force"].copy()
    m["a0/obs/modality/force"][1, 0] = 1e300
    return "a0/obs/modality/force"


def _modalities_differ(m):
    m["a0/pipeline/modalities"] = np.array(["force", "texture"])
    return "a0/pipeline/modalities"


def _classes_differ(m):
    meta = json.loads(m["a0/model/meta"].tobytes())
    meta["classes"] = ["old0", "old1", "oldX"]
    m["a0/model/meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    return "a0/model/meta"


def _unknown_member(m):
    m["junk"] = np.zeros(10)
    return "junk"


def _member_of_no_action(m):
    m["a7/obs/objects"] = np.array(["x"])
    return "a7/obs/objects"


@pytest.mark.parametrize(
    "corrupt",
    [
        _corrupt_pipeline_shape,
        _integer_object_names,
        _actions_as_a_string,
        _missing_member,
        _labels_differ,
        _model_features_wrong_width,
        _non_finite,
        _huge_feature,
        _modalities_differ,
        _classes_differ,
        _unknown_member,
        _member_of_no_action,
    ],
)
def test_corrupt_members_are_named(good, tmp_path, corrupt):
    members = _members(good)
    member = corrupt(members)
    bad = _write(tmp_path / "bad.npz", members)
    with pytest.raises(PriorFileError, match=member.replace("/", "/")) as info:
        PriorKnowledge.load(bad)
    assert str(bad) in str(info.value)


@pytest.mark.parametrize("member", ["a0/model/X", "zeros"])
def test_declared_sizes_are_checked_before_reading(good, tmp_path, member):
    bad = tmp_path / "huge.npz"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.infolist():
            if item.filename != member + ".npy":
                dst.writestr(item, src.read(item))
        dst.writestr(member + ".npy", npy_header((10**11,)))
    assert 10**11 * 8 > PRIOR_FILE_MAX_BYTES
    with pytest.raises(PriorFileError, match=member):
        PriorKnowledge.load(bad)


def test_object_arrays_are_refused(good, tmp_path):
    bad = tmp_path / "obj.npz"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.infolist():
            if item.filename != "a0/obs/objects.npy":
                dst.writestr(item, src.read(item))
        dst.writestr("a0/obs/objects.npy", npy_header((3,), "|O"))
    with pytest.raises(PriorFileError, match="a0/obs/objects"):
        PriorKnowledge.load(bad)


def test_learn_refuses_a_corrupt_prior_before_anything_moves(good, tmp_path, capsys):
    members = _members(good)
    _integer_object_names(members)
    bad = _write(tmp_path / "bad.npz", members)
    out = tmp_path / "run"
    argv = ["learn", "--robot", "sim", "--prior", str(bad), "--objects", "towel,cork_board"]
    assert main([*argv, "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "a0/obs/objects" in err and "Traceback" not in err
    assert not out.exists()
    assert main(["prior", "inspect", str(bad)]) == 1
    assert "a0/obs/objects" in capsys.readouterr().err


def test_an_unknown_member_is_never_opened(good, tmp_path, monkeypatch):
    # The report: 3.2 MB of compressed zeros (3 GB) made `inspect` and `learn` use 3.1 GB.
    members = _members(good)
    members["zeros"] = np.zeros(1000)
    bad = _write(tmp_path / "zeros.npz", members)
    opened = opened_members(monkeypatch)
    with pytest.raises(PriorFileError, match="zeros"):
        PriorKnowledge.load(bad)
    assert "zeros.npy" not in opened


def _flip_a_bit(data: bytearray, info: zipfile.ZipInfo, where: float) -> None:
    """One bit flipped inside ``info``'s stored (compressed) bytes, at ``where`` of the way."""
    start = info.header_offset
    name_len, extra_len = (
        int.from_bytes(data[start + 26 : start + 28], "little"),
        int.from_bytes(data[start + 28 : start + 30], "little"),
    )
    body = start + 30 + name_len + extra_len
    data[body + int(where * (info.compress_size - 1))] ^= 0x10


def test_a_flipped_bit_in_any_compressed_member_is_one_line(good, tmp_path, capsys):
    """A damaged deflate stream fails before its CRC is checked (zlib's own error): it is a
    damaged prior-knowledge file all the same, in one line, wherever the bit is."""
    original = good.read_bytes()
    touches = tmp_path / "touches.csv"  # (recognise checks its input exists before the library)
    touches.write_text("object,action,trial,force.0\no,a,0,1.0\n")
    with zipfile.ZipFile(good) as zf:
        infos = [i for i in zf.infolist() if i.compress_type == zipfile.ZIP_DEFLATED]
    assert len(infos) >= 8
    for info in infos:
        for where in (0.0, 0.3, 0.6):  # (the last byte may be padding nothing decodes)
            data = bytearray(original)
            _flip_a_bit(data, info, where)
            bad = tmp_path / "bad.npz"
            bad.write_bytes(bytes(data))
            for argv in (
                ["prior", "inspect", str(bad)],
                ["recognise", "--prior", str(bad), str(touches)],
            ):
                assert main(argv) == 1, (info.filename, where)
                err = capsys.readouterr().err.strip().splitlines()
                assert len(err) == 1 and str(bad) in err[0], (info.filename, where, err)


@pytest.mark.parametrize(
    "key, value",
    [
        ("provenance", ["a.npz", "b.npz"]),
        ("provenance", [1, 2]),
        ("provenance", [{"source": "a.npz", "objects": "old0"}]),
        ("provenance", [{"source": "a.npz", "objects": ["old0"], "trials": [1]}]),
        ("merged_from", "a.npz"),
        ("action_definitions", "P1"),
        ("action_definitions", 7),
        ("action_definitions", {"P1": "press"}),
        ("action_definitions", {"P1": {"force": "x", "speed": [1]}}),
        ("action_definitions", {"P1": {"name": "P1", "movement": "press", "depth": "x"}}),
        ("action_definitions", {"P1": {"name": "S1", "movement": "press"}}),
        ("feature_table_columns", {"P1": ["force.0"]}),
    ],
)
def test_forged_metadata_is_refused_where_the_file_is_read(good, tmp_path, capsys, key, value):
    """Metadata that other code reads (merge reads provenance and action definitions) is of the
    shape it reads, or the file is refused by every command, in one line naming the entry."""
    members = _members(good)
    meta = _meta(members)
    meta["metadata"][key] = value
    _set_meta(members, meta)
    bad = _write(tmp_path / "forged.npz", members)
    with pytest.raises(PriorFileError, match=f"metadata '{key}' must be"):
        PriorKnowledge.load(bad)
    merged = tmp_path / "merged.npz"
    for argv in (
        ["prior", "inspect", str(bad)],
        ["prior", "merge", str(good), str(bad), "-o", str(merged)],
    ):
        assert main(argv) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and key in err[0] and str(bad) in err[0], err
    assert not merged.exists()


def test_a_file_that_lost_its_cross_modal_whitening_is_refused(tmp_path, capsys):
    """The metric whitened across modalities is one member per action; a file whose metadata
    says it has one and lacks it (or the reverse) is damaged, not a metric of another kind."""
    priors, _, means = make_world(n_prior=3)
    path = tmp_path / "joint.npz"
    prior = PriorKnowledge.build(draw(means, priors, 8, seed=1), seed=0)
    prior.save(path)
    members = _members(path)
    joint = [k for k in members if k.endswith("/pipeline/joint")]
    assert joint and _meta(members)["joint"], "the world's metric must whiten across modalities"
    del members[joint[0]]
    bad = _write(tmp_path / "lost.npz", members)
    with pytest.raises(PriorFileError, match="pipeline/joint .*missing"):
        PriorKnowledge.load(bad)
    assert main(["prior", "inspect", str(bad)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pipeline/joint" in err[0], err
    # A file written before the list existed says nothing: it is read as it is.
    members = _members(path)
    meta = _meta(members)
    del meta["joint"]
    _set_meta(members, meta)
    PriorKnowledge.load(_write(tmp_path / "older.npz", members))
