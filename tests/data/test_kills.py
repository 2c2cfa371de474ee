"""Killing any command that writes to a data set, at any moment, leaves a file aptkt reads and
``aptkt dataset repair`` makes appendable; a file cut short is reported and repaired honestly."""

from __future__ import annotations

import os
import random
import shutil
import signal
import tempfile
import time
from pathlib import Path

import h5py
import pytest

from aptkt.actions import PAPER_ACTIONS
from aptkt.cli import main
from aptkt.data import DatasetReader, DatasetWriter, repair
from aptkt.runtime.generation import GenerationPlan, generate

OBJECTS = ("towel", "cork_board", "rough_sponge")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    path = tmp_path_factory.mktemp("kills") / "base.h5"
    plan = GenerationPlan(OBJECTS, (PAPER_ACTIONS["P1"],), 2, seed=2)
    generate(path, plan, progress=False)
    return path


def _in_child(argv: list[str]) -> int:
    """Fork a process running ``aptkt argv`` (aptkt is already imported: no start-up time)."""
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        try:
            code = main(argv)
        except BaseException:  # noqa: BLE001 - the child must end by os._exit, whatever happens
            code = 99
        os._exit(code)
    return pid


def _commands(path: Path) -> dict[str, list[str]]:
    more = ["--objects", ",".join(OBJECTS), "--actions", "P1", "-n", "3", "--seed", "2"]
    return {
        "features": ["dataset", "features", str(path), "--no-progress"],
        "resume": ["dataset", "generate", "-o", str(path), "--resume", "--no-progress", *more],
        "repair": ["dataset", "repair", str(path), "--no-backup"],
        # (--force: every kill runs the build again onto the same prior file.)
        "prior": ["prior", "build", str(path), "-o", str(path.with_suffix(".npz")), "--force"],
    }


def _leftovers(d: Path) -> list[str]:
    mine = [p.name for p in d.iterdir() if p.suffix not in (".h5", ".npz")]
    private = [p.name for p in Path(tempfile.gettempdir()).glob("work.h5.*.reading")]
    return mine + private


@pytest.mark.slow
def test_fifty_kills_at_random_moments(base, tmp_path):
    rng = random.Random(12)
    work = tmp_path / "work.h5"
    # How long each command takes unkilled: the kills are spread over that time.
    duration = {}
    for name in _commands(work):
        shutil.copy(base, work)
        t0 = time.perf_counter()
        _, status = os.waitpid(_in_child(_commands(work)[name]), 0)
        duration[name] = time.perf_counter() - t0
        assert os.waitstatus_to_exitcode(status) == 0, name
    killed = 0
    for k in range(50):
        name = list(duration)[k % len(duration)]
        shutil.copy(base, work)
        pid = _in_child(_commands(work)[name])
        time.sleep(rng.uniform(0, 0.9 * duration[name]))
        os.kill(pid, signal.SIGKILL)
        _, status = os.waitpid(pid, 0)
        killed += os.WIFSIGNALED(status)
        # Readable by aptkt as it is, with every recording it held before ...
        with DatasetReader(work) as rd:
            assert len(rd) >= 6, name
            assert not rd.damaged(full=True)
        assert main(["dataset", "info", str(work)]) == 0
        # ... and repair makes it appendable.
        repair(work, backup=False)
        DatasetWriter(work, "a").close()
        for p in tmp_path.glob("work.h5.*"):  # a killed run's scratch file: harmless, removed
            p.unlink()
    # Most kills land while the command runs (a loaded machine may run one faster than its
    # measured time, and then the kill comes after its end).
    assert killed >= 20, f"only {killed} of 50 kills hit a running command"


def test_a_writer_killed_outside_swmr_mode(base, tmp_path):
    """The window between opening a file for writing and the switch to SWMR (and any older
    aptkt's in-place feature writing): HDF5 then refuses every open of the file."""
    path = tmp_path / "crashed.h5"
    shutil.copy(base, path)
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        f = h5py.File(path, "a", libver="latest")
        f.flush()
        os._exit(0)
    os.waitpid(pid, 0)
    with pytest.raises(OSError, match="already open"):
        h5py.File(path, "r", swmr=True).close()  # what the bug report saw
    with DatasetReader(path) as rd:
        assert len(rd) == 6 and rd.writer_died
    assert main(["dataset", "info", str(path)]) == 0
    assert main(["dataset", "features", str(path), "--no-progress"]) == 1  # refuses: writer mark
    assert repair(path, backup=False) == 6
    with DatasetWriter(path, "a") as w:
        assert len(w) == 6
    assert main(["dataset", "features", str(path), "--no-progress"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["crashed.h5"]


def test_a_file_cut_at_half(base, tmp_path, capsys):
    path = tmp_path / "half.h5"
    data = base.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with DatasetReader(path) as rd:
        readable = len(rd) - len(rd.damaged())
        keys = [rd.key(i) for i in range(len(rd)) if i not in rd.damaged()]
    assert 0 < readable < 6
    assert main(["dataset", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"{readable} recordings" in out and "DAMAGED" in out
    assert main(["dataset", "features", str(path), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "damaged" in err and "Traceback" not in err
    assert main(["dataset", "repair", str(path)]) == 0
    with DatasetReader(path) as rd:
        assert rd.keys() == keys and not rd.damaged()
        for i, key in enumerate(keys):
            with DatasetReader(base) as orig:
                j = orig.keys().index(key)
                assert (orig.raw(j)["t_ns"] == rd.raw(i)["t_ns"]).all()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["half.h5", "half.h5.crashed"]


def test_repair_leaves_no_temporary_file_on_failure(base, tmp_path, monkeypatch):
    path = tmp_path / "f.h5"
    shutil.copy(base, path)
    calls = {"n": 0}
    original = DatasetWriter._append_raw

    def failing(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError(28, "No space left on device")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(DatasetWriter, "_append_raw", failing)
    with pytest.raises(OSError):
        repair(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.h5"]
    assert path.read_bytes() == base.read_bytes()


def _appears(d: Path, name: str, pid: int) -> bool:
    """Wait until a file named ``name`` (or a side file named after it) appears in ``d``;
    False if the child ended first. Looked for every 0.2 ms, a fifth of the 1 ms between the
    kills' moments: spinning without a pause took a core from the child and the other tests."""
    while True:
        if any(p.name.startswith(name) for p in d.iterdir()):
            return True
        done, _ = os.waitpid(pid, os.WNOHANG)
        if done:
            return False
        time.sleep(0.0002)


def _early(tmp: Path) -> dict[str, tuple[list[str], list[str], Path]]:
    """Per command: its arguments, those that complete the file afterwards, and the file."""
    d = tmp / "early"
    sim = ["--objects", "towel", "--actions", "P1", "-n", "2", "--no-progress"]
    gen = ["dataset", "generate", "-o", str(d / "g.h5"), "--seed", "2", *sim]
    col = ["collect", "--robot", "sim", "--thermal-wait", "0", "-o", str(d / "c.h5"), *sim]
    rep = ["reproduce", "fig7", "--quick", "-j", "1", "--no-progress", "-o", str(d / "r")]
    return {
        "generate": (gen, [*gen, "--resume"], d / "g.h5"),
        "collect": (col, [*col, "--resume"], d / "c.h5"),
        # Its help: "rerun the same command after an interruption and it resumes".
        "reproduce": (rep, rep, d / "r" / "data-quick-seed0.h5"),
    }


@pytest.mark.parametrize("name", ["generate", "collect", "reproduce"])
@pytest.mark.slow
def test_kills_in_the_first_milliseconds_of_a_file(tmp_path, name):
    """SIGKILL 0-3 ms after a data set file appears left, in 5 of 20 tries, a 48-byte file
    that nothing opened (not `dataset info`, `--resume`, `repair` or a rerun). A file now
    appears whole (created under another name, renamed once its structure is on disk); every
    kill leaves a file aptkt opens, or none, and the rerun completes it."""
    argv, again, path = _early(tmp_path)[name]
    kills = 12 if name == "reproduce" else 20
    hit = 0
    for k in range(kills):
        shutil.rmtree(tmp_path / "early", ignore_errors=True)
        path.parent.mkdir(parents=True)
        pid = _in_child(argv)
        if not _appears(path.parent, path.name, pid):
            raise AssertionError(f"{name} ended before its file appeared")
        time.sleep((k % 4) * 0.001)  # 0, 1, 2, 3 ms after the file (or its side file) appeared
        os.kill(pid, signal.SIGKILL)
        _, status = os.waitpid(pid, 0)
        hit += os.WIFSIGNALED(status)
        if path.exists():  # aptkt opens what the kill left ...
            assert main(["dataset", "info", str(path)]) == 0, (
                f"kill {k}: {path.stat().st_size} bytes"
            )
        if k % 4 == 3 or name != "reproduce":  # ... and the rerun completes it
            assert main(again) == 0, f"kill {k}"
            if name != "reproduce":
                with DatasetReader(path) as rd:
                    assert len(rd) == 2
            # No scratch file left (a repair's backup `.crashed` is kept on purpose).
            leftovers = {p.name for p in path.parent.iterdir() if p.name.startswith(path.name)}
            assert leftovers - {path.name + ".crashed"} == {path.name}, leftovers
    assert hit == kills  # every kill landed while the command ran
