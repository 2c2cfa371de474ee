"""A data set cut short or changed on disk is never read as good data: `dataset info` reports the
damage and every command that reads the file refuses it with one line naming the file and the
recording — or, where the damage touches nothing it reads, gives exactly the undamaged result."""

from __future__ import annotations

import csv
import os
import re
import shutil
import signal
import time

import h5py
import numpy as np
import pytest

from aptkt.actions import PAPER_ACTIONS
from aptkt.cli import main
from aptkt.data import DatasetReader, DatasetWriter, repair
from aptkt.learning.dataset import extract_features
from aptkt.runtime.generation import GenerationPlan, generate

OBJECTS = ("towel", "cork_board", "rough_sponge", "metal_toolbox")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("integrity")
    path = d / "d.h5"
    actions = (PAPER_ACTIONS["P1"], PAPER_ACTIONS["S1"])
    generate(path, GenerationPlan(OBJECTS, actions, 3, seed=4), progress=False)
    extract_features(path, progress=False)
    # The same file with its features stored as an older aptkt stored them: contiguous, with
    # no checksum (the layout the truncated file of the bug report had).
    old = d / "old.h5"
    shutil.copy(path, old)
    with h5py.File(old, "a") as f:
        for action in f["features"]:
            g = f["features"][action]
            for name in list(g):
                values = g[name][...]
                del g[name]
                g.create_dataset(name, data=values)
    return d


def _one_line(capsys, label: str) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert "Traceback" not in err and len(lines) == 1, err
    assert lines[0].startswith(f"{label}: error: "), lines[0]
    return lines[0]


def _table(path) -> list[list[str]]:
    with open(path, newline="") as fh:
        return list(csv.reader(fh))


@pytest.mark.parametrize("layout", ["d.h5", "old.h5"])
@pytest.mark.parametrize("cut", [200, 1000, 4000, 20000, 60000, "half"])
def test_a_truncated_data_set_is_refused_or_read_exactly(data, tmp_path, capsys, layout, cut):
    """`head -c -1000 d.h5 > t.h5`: `dataset info` reported no damage, `export-features` wrote
    125 thermal values of one recording as 0.0 and `prior build` learnt from them."""
    source = data / layout
    whole = source.read_bytes()
    n = len(whole) // 2 if cut == "half" else cut
    t = tmp_path / "t.h5"
    t.write_bytes(whole[:-n])
    assert main(["dataset", "export-features", str(source), "-o", str(tmp_path / "ref.csv")]) == 0
    capsys.readouterr()

    if main(["dataset", "info", str(t)]) == 0:
        report = capsys.readouterr().out
    else:  # the cut took HDF5's own structure (written last with the features): said so
        report = _one_line(capsys, "aptkt dataset info")
        assert "DAMAGED" not in report and "no recording can be recovered" in report
        report = "DAMAGED"
    code = main(["dataset", "export-features", str(t), "-o", str(tmp_path / "t.csv")])
    if code == 0:
        # Nothing this command reads was damaged: every value is the undamaged file's.
        capsys.readouterr()
        assert _table(tmp_path / "t.csv") == _table(tmp_path / "ref.csv")
    else:
        line = _one_line(capsys, "aptkt dataset export-features")
        assert str(t) in line and "damaged" in line
        named = r"(towel|cork_board|rough_sponge|metal_toolbox)/(P1|S1)/trial \d|every (P1|S1) rec"
        assert re.search(named + "|no recording can be recovered", line), line
        assert "DAMAGED" in report  # and `dataset info` says so
        assert not (tmp_path / "t.csv").exists()
        for argv, label in (
            (["prior", "build", str(t), "-o", str(tmp_path / "p.npz")], "aptkt prior build"),
            (["dataset", "features", str(t), "--no-progress"], "aptkt dataset features"),
        ):
            assert main(argv) == 1
            assert str(t) in _one_line(capsys, label)
        assert not (tmp_path / "p.npz").exists()
    if cut == 1000:  # the bug report's case: the end of the stored features is gone
        assert code == 1 and "DAMAGED: stored features" in report


def test_every_reader_refuses_a_truncated_data_set(data, tmp_path, capsys):
    """`learn --test` and `reproduce --data` too: before the robot connects or anything is
    simulated."""
    from aptkt.learning import PriorKnowledge
    from aptkt.learning.dataset import load_observations

    t = tmp_path / "t.h5"
    t.write_bytes((data / "d.h5").read_bytes()[:-1000])
    prior = tmp_path / "p.npz"
    table = load_observations(data / "d.h5", actions=["P1"], objects=["towel", "cork_board"])
    PriorKnowledge.build(table).save(prior)
    learn = ["learn", "--robot", "sim", "--prior", str(prior), "--actions", "P1"]
    learn += [
        "--objects",
        "rough_sponge,metal_toolbox",
        "--test",
        str(t),
        "-o",
        str(tmp_path / "l"),
    ]
    reproduce = ["reproduce", "fig7", "--quick", "--data", str(t), "-o", str(tmp_path / "r")]
    for argv, label in ((learn, "aptkt learn"), (reproduce, "aptkt reproduce")):
        assert main(argv) == 1
        line = _one_line(capsys, label)
        assert str(t) in line and "damaged (the file is cut short)" in line
        assert re.search(r"/S1/trial \d", line), line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.npz", "t.h5"]


def test_repair_then_features_recovers_a_truncated_file(data, tmp_path, capsys):
    t = tmp_path / "t.h5"
    t.write_bytes((data / "d.h5").read_bytes()[:-1000])
    assert main(["dataset", "repair", str(t)]) == 0
    assert main(["dataset", "features", str(t), "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["dataset", "export-features", str(t), "-o", str(tmp_path / "t.csv")]) == 0
    assert (
        main(["dataset", "export-features", str(data / "d.h5"), "-o", str(tmp_path / "r.csv")]) == 0
    )
    assert _table(tmp_path / "t.csv") == _table(tmp_path / "r.csv")


def _corrupt_metadata(path, i: int) -> None:
    """Replace recording ``i``'s metadata JSON by bytes of the same length that are not JSON
    (through HDF5, so that the compressed chunk stays valid: only the content is wrong)."""
    with DatasetReader(path) as rd:
        row = rd.index[i]
    with h5py.File(path, "a") as f:
        meta = f["recordings/metadata"]
        start = int(row["meta_start"])
        meta[start : start + 8] = np.frombuffer(b"#garbage", dtype=np.uint8)


def test_corrupted_metadata_json_is_one_error_line(data, tmp_path, capsys):
    """A changed `recordings/metadata` made `dataset features` end in a JSONDecodeError
    traceback."""
    path = tmp_path / "m.h5"
    shutil.copy(data / "d.h5", path)
    with DatasetReader(path) as rd:
        name = "{}/{}/trial {}".format(*rd.key(4))
    _corrupt_metadata(path, 4)
    for argv, label in (
        (["dataset", "features", str(path), "--no-progress"], "aptkt dataset features"),
        (
            [
                "dataset",
                "export-features",
                str(path),
                "--actions",
                "S1",
                "-o",
                str(tmp_path / "x.csv"),
            ],
            "aptkt dataset export-features",
        ),
        (
            ["prior", "build", str(path), "-o", str(tmp_path / "p.npz"), "--actions", "P1,S1"],
            "aptkt prior build",
        ),
    ):
        code = main(argv)
        if code == 0 and label != "aptkt dataset features":
            capsys.readouterr()  # read stored features only: the recording was not needed
            continue
        line = _one_line(capsys, label)
        assert str(path) in line and "recording 4" in line and name in line, line
    assert main(["dataset", "info", str(path), "--check"]) == 0
    out = capsys.readouterr().out
    assert "DAMAGED: 1 recording(s)" in out and name in out
    assert repair(path) == 2 * 3 * len(OBJECTS) - 1  # the others are kept


def test_changed_feature_bytes_fail_their_checksum(data, tmp_path, capsys):
    path = tmp_path / "f.h5"
    shutil.copy(data / "d.h5", path)
    with h5py.File(path, "r") as f:
        ds = f["features/P1/force"]
        info = ds.id.get_chunk_info(0)
        assert ds.fletcher32
    with open(path, "r+b") as fh:  # one byte inside the stored values, behind HDF5's back
        fh.seek(info.byte_offset + 3)
        byte = fh.read(1)
        fh.seek(info.byte_offset + 3)
        fh.write(bytes([byte[0] ^ 0xFF]))
    assert main(["dataset", "export-features", str(path), "-o", str(tmp_path / "x.csv")]) == 1
    line = _one_line(capsys, "aptkt dataset export-features")
    assert "force features of P1 are damaged" in line and str(path) in line
    assert main(["dataset", "info", str(path), "--check"]) == 0
    assert "DAMAGED: stored features P1/force" in capsys.readouterr().out


def test_a_file_left_empty_by_an_older_writer_starts_afresh(tmp_path, capsys):
    """What a kill in the first milliseconds left before files were created whole: 0 bytes, or
    HDF5's 48-byte superblock. It holds nothing; --resume and repair start it afresh."""
    empty, sb = tmp_path / "e.h5", tmp_path / "s.h5"
    empty.write_bytes(b"")
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child: create as HDF5 does, die before any flush
        f = h5py.File(sb, "w", libver="latest")
        os._exit(0 if f else 1)
    os.waitpid(pid, 0)
    assert sb.stat().st_size == 48
    for path in (empty, sb):
        assert main(["dataset", "info", str(path)]) == 0
        assert "holds nothing" in capsys.readouterr().out
    gen = ["dataset", "generate", "-o", str(sb), "--objects", "towel", "--actions", "P1"]
    assert main([*gen, "-n", "2", "--seed", "3", "--resume", "--no-progress"]) == 0
    with DatasetReader(sb) as rd:
        assert len(rd) == 2 and rd.description["seed"] == 3
    assert repair(empty, backup=False) == 0
    DatasetWriter(empty, "a").close()
    # Not every small file: one that is not HDF5 is no data set, and is refused.
    other = tmp_path / "notes.h5"
    other.write_text("my notes")
    assert main([*gen, "-n", "1", "-o", str(other), "--resume", "--no-progress"]) == 1
    capsys.readouterr()
    assert other.read_text() == "my notes"


def test_a_file_appears_only_whole(tmp_path):
    """While a data set file is created it exists under `<name>.creating`; at its own name
    there is never less than an empty data set."""
    path = tmp_path / "w.h5"
    seen = []
    original = h5py.File

    def spy(name, mode="r", *args, **kwargs):
        if mode == "w":
            seen.append((os.fspath(name), path.exists()))
        return original(name, mode, *args, **kwargs)

    h5py.File = spy
    try:
        DatasetWriter(path, "w", description={"x": 1}).close()
    finally:
        h5py.File = original
    assert seen == [(str(path) + ".creating", False)]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.h5"]
    with DatasetReader(path) as rd:
        assert len(rd) == 0 and rd.description == {"x": 1}


def test_a_name_near_the_limit_takes_the_side_files_suffixes(tmp_path):
    """A name near the file system's limit (255 bytes) is created through a temporary name and
    read, after its writer died, through a private copy: neither may exceed the limit."""
    path = tmp_path / ("n" * 245 + ".h5")
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child: a writer killed outside SWMR mode
        w = DatasetWriter(path, "w")
        w.close()
        f = h5py.File(path, "a", libver="latest")
        f.flush()
        os.kill(os.getpid(), signal.SIGKILL)
        time.sleep(10)
    os.waitpid(pid, 0)
    with DatasetReader(path) as rd:
        assert rd.writer_died and len(rd) == 0


@pytest.mark.parametrize("keep", [10_000, 20_000, 40_000])
def test_a_file_cut_to_its_first_bytes_is_one_line(data, tmp_path, capsys, keep):
    """Only the first tens of kB left: HDF5 finds metadata whose checksum never matches and
    raises a RuntimeError after its read attempts, which ended `dataset info` in a traceback."""
    plain = tmp_path / "plain.h5"  # no features: the index's chunks lie in the first bytes
    plan = GenerationPlan(OBJECTS[:3], (PAPER_ACTIONS["P1"],), 2, seed=2)
    generate(plain, plan, progress=False)
    t = tmp_path / "t.h5"
    t.write_bytes(plain.read_bytes()[:keep])
    if main(["dataset", "info", str(t)]) == 0:
        assert "DAMAGED" in capsys.readouterr().out
    else:
        line = _one_line(capsys, "aptkt dataset info")
        assert str(t) in line and "damaged" in line
