"""Nothing is written through a link: a symbolic link where a command writes a result is
replaced by the result, and the file it points at (outside the output directory) keeps every
byte; a dangling link creates nothing at its target, and counts as an earlier result."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.learning import Observations
from aptkt.learning.feature_table import write_feature_table

PRECIOUS = "precious: not aptkt's to overwrite\n"


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """A table of 8 objects × 8 trials on a line (one action, two modalities) and a library of
    its objects."""
    d = tmp_path_factory.mktemp("links")
    rng = np.random.default_rng(0)
    objects = np.repeat([f"o{k}" for k in range(8)], 8)
    centre = np.repeat(3.0 * np.arange(8), 8)
    shape = np.column_stack([centre, np.zeros_like(centre)]) + rng.normal(size=(64, 2))
    obs = Observations(
        "touch",
        {"shape": shape, "noise": rng.normal(size=(64, 1))},
        objects,
        np.tile(np.arange(8), 8),
    )
    write_feature_table(d / "t.csv", {"touch": obs})
    assert main(["prior", "build", str(d / "t.csv"), "-o", str(d / "lib.npz")]) == 0
    return d


def _commands(work: Path) -> dict[str, list[str]]:
    table = str(work / "t.csv")
    quick = ["--budget", "1", "-j", "1", "--no-progress"]
    return {
        "benchmark": ["benchmark", table, "--groups", "2", "--new", "3", "--priors", "2"]
        + ["--choices", "random", *quick],
        "benchmark --recognition": ["benchmark", table, "--recognition", "--priors", "5"]
        + ["--new", "3", "--groups", "2", "-j", "1", "--no-progress"],
        "benchmark --lifelong": ["benchmark", table, "--lifelong", "--orders", "2", "--new", "2"]
        + quick,
        "learn --table": ["learn", "--table", table, "--prior-objects", "o0,o1,o2"]
        + ["--objects", "o3,o4", "--budget", "1", "--runs", "1"],
        "recognise": ["recognise", "--prior", str(work / "lib.npz"), "--table", table],
    }


COMMANDS = list(_commands(Path(".")))


def _files(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.is_file())


@pytest.mark.parametrize("command", COMMANDS)
def test_a_link_in_the_output_is_replaced_and_its_target_kept(work, tmp_path, command, capsys):
    argv = _commands(work)[command]
    first = tmp_path / "first"
    assert main([*argv, "-o", str(first)]) == 0, capsys.readouterr().err
    written = _files(first)
    assert "summary.json" in written, written
    # Every file the command writes is a link to a file outside, or a dangling link.
    outside, out = tmp_path / "outside", tmp_path / "out"
    outside.mkdir()
    out.mkdir()
    for k, name in enumerate(written):
        target = outside / name
        if k % 2 == 0:
            target.write_text(PRECIOUS)
        (out / name).symlink_to(target)
    capsys.readouterr()
    assert main([*argv, "-o", str(out)]) == 1  # links are earlier results too
    assert "--force" in capsys.readouterr().err
    assert main([*argv, "-o", str(out), "--force"]) == 0, capsys.readouterr().err
    for k, name in enumerate(written):
        assert not (out / name).is_symlink() and (out / name).is_file(), name
        if k % 2 == 0:
            assert (outside / name).read_text() == PRECIOUS, name
    assert _files(outside) == [n for k, n in enumerate(written) if k % 2 == 0]


@pytest.mark.parametrize("command", COMMANDS)
def test_a_dangling_summary_link_is_an_earlier_result(work, tmp_path, command, capsys):
    out, target = tmp_path / "out", tmp_path / "elsewhere" / "summary.json"
    target.parent.mkdir()
    out.mkdir()
    (out / "summary.json").symlink_to(target)
    assert main([*_commands(work)[command], "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--force" in err[0], err
    assert not os.path.lexists(target) and (out / "summary.json").is_symlink()


def test_prior_build_replaces_a_link_not_its_target(work, tmp_path, capsys):
    target, link = tmp_path / "precious.npz", tmp_path / "p.npz"
    target.write_text(PRECIOUS)
    link.symlink_to(target)
    argv = ["prior", "build", str(work / "t.csv"), "-o", str(link)]
    assert main(argv) == 1 and "--force" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0
    assert target.read_text() == PRECIOUS and link.is_file() and not link.is_symlink()
    dangling = tmp_path / "d.npz"
    dangling.symlink_to(tmp_path / "nowhere.npz")
    assert main(["prior", "build", str(work / "t.csv"), "-o", str(dangling)]) == 1
    assert not (tmp_path / "nowhere.npz").exists()


def test_a_data_set_is_never_created_nor_appended_to_through_a_link(tmp_path, capsys):
    """A dangling link where a data set is written counts as an earlier file (--force replaces
    the link by the file, never creating its target); appending — `--resume`, `learn
    --record` — would write through a link in place, so it is refused in one line."""
    target, link = tmp_path / "elsewhere.h5", tmp_path / "d.h5"
    link.symlink_to(target)
    argv = ["dataset", "generate", "-o", str(link), "--objects", "towel", "--actions", "P1"]
    argv += ["-n", "1", "-j", "1", "--no-progress"]
    for extra, fragment in (([], "exists"), (["--resume"], "")):
        assert main([*argv, *extra]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and fragment in err[0], err
    assert link.is_symlink() and not target.exists()
    assert main([*argv, "--force"]) == 0
    assert not link.is_symlink() and link.is_file() and not target.exists()
    # learn --record appends: a link there is refused before anything moves.
    record = tmp_path / "record.h5"
    record.symlink_to(tmp_path / "elsewhere-record.h5")
    capsys.readouterr()
    data, lib = tmp_path / "prior.h5", tmp_path / "prior.npz"
    gen = ["dataset", "generate", "-o", str(data), "--objects", "rough_sponge,paper_box"]
    assert main([*gen, "--actions", "P1", "-n", "2", "-j", "1", "--no-progress"]) == 0
    assert main(["prior", "build", str(data), "-o", str(lib)]) == 0
    learn = ["learn", "--robot", "sim", "--prior", str(lib), "--objects", "towel,cork_board"]
    assert main([*learn, "--record", str(record), "-o", str(tmp_path / "run")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "symbolic link" in err[0], err
    assert not (tmp_path / "run").exists() and not (tmp_path / "elsewhere-record.h5").exists()
