"""Every sub-command against a table of user mistakes: each ends in one
``aptkt <command>: error: ...`` line naming the problem, exit code 1, no traceback, and no
(empty) output directory left behind."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from aptkt.actions import PAPER_ACTIONS
from aptkt.cli import main
from aptkt.learning import PriorKnowledge
from aptkt.learning.dataset import extract_features, load_observations
from aptkt.runtime.generation import GenerationPlan, generate

PYTHON_DIR = Path(__file__).resolve().parents[2] / "python"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("mistakes")
    data = d / "d.h5"
    objects = ("rough_sponge", "metal_toolbox", "towel")
    generate(data, GenerationPlan(objects, (PAPER_ACTIONS["P1"],), 3, seed=1), progress=False)
    # Stored features (loading only reads): the half-length copy below then cuts through the
    # file's structure, not only through recordings.
    extract_features(data, progress=False)
    table = load_observations(data, objects=objects[:2])
    PriorKnowledge.build(table).save(d / "p.npz")
    (d / "afile").write_text("a file")
    (d / "dir").mkdir()
    truncated = d / "trunc.h5"
    truncated.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    return d


DATA_GEN = ["--objects", "towel", "--actions", "P1", "-n", "1", "--no-progress"]
SIM = ["--robot", "sim"]

# (arguments, a fragment the error line must contain); {d} is the fixture directory.
MISTAKES = [
    # an output path that is a file, or lies under a file
    (["demo", "-o", "{d}/afile", "--quick"], "is a file"),
    (["dataset", "generate", "-o", "{d}/afile/x.h5", *DATA_GEN], "is a file"),
    (["reproduce", "fig6", "-o", "{d}/afile", "--quick"], "is a file"),
    (
        ["learn", *SIM, "--prior", "{d}/p.npz", "--objects", "towel,cork_board", "-o", "{d}/afile"],
        "is a file",
    ),
    (["prior", "build", "{d}/d.h5", "-o", "{d}/afile/x.npz"], "is a file"),
    (["collect", *SIM, "--objects", "towel", "-n", "1", "-o", "{d}/afile/x.h5"], "is a file"),
    # an output that is an input: replacing it would destroy what is read, --force or not
    (["prior", "build", "{d}/d.h5", "-o", "{d}/d.h5", "--force"], "is the input DATASET|TABLE"),
    (
        ["dataset", "export-features", "{d}/d.h5", "-o", "{d}/d.h5", "--force"],
        "is the input DATASET",
    ),
    (
        ["dataset", "generate", "-o", "{d}/afile", "--actions-file", "{d}/afile", "--force"]
        + DATA_GEN,
        "is the input --actions-file",
    ),
    (
        [*"collect --robot sim --objects towel -n 1 --force".split(), "-o", "{d}/afile"]
        + ["--objects-file", "{d}/afile"],
        "is the input --objects-file",
    ),
    (
        ["learn", *SIM, "--prior", "{d}/p.npz", "--objects", "towel,cork_board"]
        + ["-o", "{d}/new/L", "--record", "{d}/p.npz"],
        "is the input --prior",
    ),
    # an input of the wrong kind, said as what it is
    (["benchmark", "{d}/trunc.h5", "-o", "{d}/new/b"], "is not a readable HDF5 file"),
    (["benchmark", "{d}/p.npz", "-o", "{d}/new/b"], "(.npz); as TABLE give a feature table"),
    (
        ["prior", "build", "{d}/p.npz", "-o", "{d}/new/x.npz"],
        "(.npz); as DATASET|TABLE give a data set",
    ),
    (
        ["recognise", "--prior", "{d}/p.npz", "{d}/p.npz", "-o", "{d}/new/r"],
        "give it with --prior, and as DATASET|TABLE give a data set (HDF5) or a feature table",
    ),
    (
        ["recognise", "--prior", "{d}/p.npz", "--table", "{d}/p.npz", "-o", "{d}/new/r"],
        "give it with --prior, and as --table give a feature table (.csv, .h5)",
    ),
    (
        ["learn", "--table", "{d}/trunc.h5", "--objects", "towel,cork_board", "-o", "{d}/new/l"],
        "is not a readable HDF5 file (damaged or cut short?); aptkt learn reads a feature table",
    ),
    # an output path that is a directory
    (["dataset", "generate", "-o", "{d}/dir", "--force", *DATA_GEN], "is a directory"),
    (["prior", "build", "{d}/d.h5", "-o", "{d}/dir"], "is a directory"),
    # negative values
    (["dataset", "generate", "-o", "{d}/new/s.h5", "--seed", "-5", *DATA_GEN], "--seed"),
    (
        ["dataset", "generate", "-o", "{d}/new/s.h5", "--first-trial", "-3", *DATA_GEN],
        "--first-trial",
    ),
    (["prior", "build", "{d}/d.h5", "-o", "{d}/new/r.npz", "--restarts", "-1"], "--restarts"),
    (["demo", "-o", "{d}/new/demo", "--seed", "-1", "--quick"], "--seed"),
    (["reproduce", "fig6", "-o", "{d}/new/r", "--seed", "-1", "--quick"], "--seed"),
    (
        [
            "collect",
            *SIM,
            "--objects",
            "towel",
            "-n",
            "1",
            "-o",
            "{d}/new/c.h5",
            "--first-trial",
            "-3",
        ],
        "--first-trial",
    ),
    (
        [
            "learn",
            *SIM,
            "--prior",
            "{d}/p.npz",
            "--objects",
            "towel,cork_board",
            "-o",
            "{d}/new/l",
            "--seed",
            "-2",
        ],
        "--seed",
    ),
    # unknown names, too few or duplicate objects
    (["dataset", "features", "{d}/d.h5", "--actions", "Z9"], "Z9"),
    (["prior", "build", "{d}/d.h5", "-o", "{d}/new/z.npz", "--actions", "Z9"], "Z9"),
    (
        ["prior", "build", "{d}/d.h5", "-o", "{d}/new/o.npz", "--objects", "rough_sponge"],
        "at least two",
    ),
    (
        [
            "prior",
            "build",
            "{d}/d.h5",
            "-o",
            "{d}/new/o.npz",
            "--objects",
            "rough_sponge,metl_toolbox",
        ],
        "metl_toolbox",
    ),
    (
        [
            "prior",
            "build",
            "{d}/d.h5",
            "-o",
            "{d}/new/o.npz",
            "--objects",
            "rough_sponge,rough_sponge",
        ],
        "twice",
    ),
    (
        [
            "dataset",
            "generate",
            "-o",
            "{d}/new/s.h5",
            "--objects",
            "towel,towel",
            "--actions",
            "P1",
            "-n",
            "1",
        ],
        "twice",
    ),
    (
        ["learn", *SIM, "--prior", "{d}/p.npz", "--objects", "towel,towel", "-o", "{d}/new/l"],
        "twice",
    ),
    (["collect", *SIM, "--objects", "towel,towl", "-n", "1", "-o", "{d}/new/c.h5"], "towl"),
    # missing and damaged inputs
    (
        [
            "learn",
            *SIM,
            "--prior",
            "{d}/missing.npz",
            "--objects",
            "towel,cork_board",
            "-o",
            "{d}/new/l",
        ],
        "no such file",
    ),
    (["prior", "inspect", "{d}/missing.npz"], "no such file"),
    (["dataset", "info", "{d}/missing.h5"], "no such file"),
    (["dataset", "features", "{d}/trunc.h5"], "damaged"),
    (["dataset", "info", "{d}/trunc.h5"], "damaged"),
    (
        ["reproduce", "fig6", "--quick", "--data", "{d}/missing.h5", "-o", "{d}/new/r"],
        "no such file",
    ),
    # contradicting options
    (
        ["dataset", "generate", "-o", "{d}/new/s.h5", "--resume", "--force", *DATA_GEN],
        "--resume and --force",
    ),
    (
        [
            "collect",
            *SIM,
            "--objects",
            "towel",
            "-n",
            "1",
            "-o",
            "{d}/new/c.h5",
            "--resume",
            "--force",
        ],
        "--resume and --force",
    ),
    (["skin", "monitor"], "PORT"),
    # names the file system refuses, values without bound: before any file is created
    (["dataset", "generate", "-o", "{d}/" + "a" * 300 + ".h5", *DATA_GEN], "is too long"),
    (["collect", *SIM, "--objects", "towel", "-n", "1", "-o", "{d}/" + "c" * 250], "too long"),
    (["reproduce", "fig7", "--quick", "-o", "{d}/new/" + "r" * 300], "is too long"),
    (["dataset", "info", "{d}/" + "i" * 300 + ".h5"], "is too long"),
    (
        ["reproduce", "fig7", "--quick", "--scheduler", "notaurl", "-o", "{d}/new/r"],
        "not a scheduler address",
    ),
    (
        [
            "collect",
            *SIM,
            "--objects",
            "towel",
            "-n",
            "1",
            "-o",
            "{d}/new/c.h5",
            "--thermal-wait",
            "inf",
        ],
        "--thermal-wait must be at most 3600",
    ),
    (
        [
            "collect",
            *SIM,
            "--objects",
            "towel",
            "-n",
            "1",
            "-o",
            "{d}/new/c.h5",
            "--thermal-wait",
            "nan",
        ],
        "--thermal-wait",
    ),
    (
        [
            "collect",
            "--robot",
            "ur10",
            "--workspace",
            "{d}/p.npz",
            "--skin",
            "/dev/null",
            "--objects",
            "towel",
            "-n",
            "1",
            "-o",
            "{d}/new/c.h5",
        ],
        "not a workspace file",
    ),  # fmt: skip
    (
        [
            "collect",
            *SIM,
            "--objects",
            "towel",
            "-n",
            "1",
            "--actions-file",
            "{d}/p.npz",
            "-o",
            "{d}/new/c.h5",
        ],
        "not an actions file",
    ),
    (
        ["dataset", "generate", "-o", "{d}/new/s.h5", "--objects-file", "{d}/p.npz", *DATA_GEN],
        "not an object library",
    ),
    (
        ["dataset", "generate", "-o", "{d}/new/s.h5", "-n", "100000000", "--no-progress"],
        "= 10500000000 trials, more than the 100000",
    ),
    (
        ["collect", *SIM, "--objects", "towel", "-n", "200000", "-o", "{d}/new/c.h5"],
        "more than the 100000",
    ),
    (
        ["dataset", "generate", "-o", "{d}/new/s.h5", "--first-trial", "3000000000", *DATA_GEN],
        "32-bit",
    ),
    (
        ["dataset", "generate", "-o", "{d}/new/s.h5", "-j", "100000", *DATA_GEN],
        "--jobs must be at most",
    ),
    (["dataset", "features", "{d}/d.h5", "-j", "100000"], "--jobs must be at most"),
    (["reproduce", "fig6", "--quick", "-j", "100000", "-o", "{d}/new/r"], "--jobs must be at most"),
    (
        ["demo", "--quick", "--runs", "1000000000", "-o", "{d}/new/demo"],
        "--runs must be at most",
    ),
    (
        ["prior", "build", "{d}/d.h5", "-o", "{d}/new/r.npz", "--restarts", "1000000000"],
        "--restarts must be at most 1000",
    ),
    (
        [
            "learn",
            *SIM,
            "--prior",
            "{d}/p.npz",
            "--objects",
            "towel,cork_board",
            "--budget",
            "1000000000",
            "-o",
            "{d}/new/l",
        ],
        "--budget must be at most",
    ),  # fmt: skip
    (
        [
            "learn",
            *SIM,
            "--prior",
            "{d}/p.npz",
            "--objects",
            "towel,cork_board",
            "--target-accuracy",
            "1.5",
            "-o",
            "{d}/new/l",
        ],
        "--target-accuracy must be an accuracy in (0, 1], got 1.5",
    ),  # fmt: skip
    (
        [
            "learn",
            *SIM,
            "--prior",
            "{d}/p.npz",
            "--objects",
            "towel,cork\x1b[2J",
            "-o",
            "{d}/new/l",
        ],
        "--objects: a name with the control character '\\x1b'",
    ),  # fmt: skip
    (
        ["collect", *SIM, "--objects", "t" * 201, "-n", "1", "-o", "{d}/new/x.h5"],
        "--objects: a name of 201 characters (at most 200)",
    ),
    # the method's alternatives: a value the learner refuses
    (
        [
            "learn",
            *SIM,
            "--prior",
            "{d}/p.npz",
            "--objects",
            "towel,cork_board",
            "--evidence-margin",
            "inf",
            "-o",
            "{d}/new/l",
        ],
        "evidence_margin must be finite",
    ),
]


def _label(argv: list[str]) -> str:
    words = [argv[0]]
    if argv[0] in ("dataset", "prior", "skin"):
        words.append(argv[1])
    return "aptkt " + " ".join(words)


@pytest.mark.parametrize(("argv", "fragment"), MISTAKES, ids=lambda v: " ".join(v)[:60])
def test_every_mistake_is_one_error_line(files, capsys, argv, fragment):
    argv = [a.replace("{d}", str(files)) for a in argv]
    before = sorted(p.name for p in files.iterdir())
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert re.match(rf"^{re.escape(_label(argv))}: error: ", lines[0]), lines[0]
    assert fragment in lines[0]
    # no output directory (nor anything else) left behind
    assert sorted(p.name for p in files.iterdir()) == before


def test_scheduler_without_dask_fails_before_any_work(files, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import fails
    out = files / "new" / "r"
    argv = ["reproduce", "fig6", "--quick", "--scheduler", "tcp://h:1", "-o", str(out)]
    assert main(argv) == 1
    assert "--scheduler needs dask" in capsys.readouterr().err
    assert not (files / "new").exists()


def _unprivileged(cmd: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """Run as a user who cannot write where the test made things read-only (root ignores file
    modes, so as root the command runs as nobody)."""
    env = {**os.environ, "PYTHONPATH": str(PYTHON_DIR)}
    prefix: list[str] = []
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        assert setpriv, "as root this test needs setpriv (util-linux) to drop privileges"
        prefix = [setpriv, "--reuid=65534", "--regid=65534", "--clear-groups"]
    return subprocess.run(
        [*prefix, sys.executable, "-m", "aptkt.cli", *cmd],
        check=False,
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.fixture
def read_only(files):
    base = Path(tempfile.mkdtemp(prefix="aptkt-ro-"))
    base.chmod(0o755)
    ro = base / "ro"
    ro.mkdir()
    shutil.copy(files / "d.h5", ro / "d.h5")
    (ro / "d.h5").chmod(0o444)
    ro.chmod(0o555)
    yield base
    ro.chmod(0o755)
    shutil.rmtree(base)


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (["reproduce", "fig6", "--quick", "-o", "ro/out"], "cannot write"),
        (["dataset", "features", "ro/d.h5"], "read-only"),
        (["dataset", "repair", "ro/d.h5"], "read-only"),
        (["dataset", "generate", "-o", "ro/new.h5", *DATA_GEN], "cannot write"),
        (["prior", "build", "ro/d.h5", "-o", "ro/p.npz"], "cannot write"),
    ],
    ids=lambda v: " ".join(v)[:40],
)
def test_read_only_places_are_one_error_line(read_only, argv, fragment):
    before = sorted(p.name for p in (read_only / "ro").iterdir())
    r = _unprivileged(argv, read_only)
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"{_label(argv)}: error: "), r.stderr
    assert fragment in lines[0]
    assert sorted(p.name for p in (read_only / "ro").iterdir()) == before


# What argparse itself finds (an unknown option, a missing required argument, a value that is
# not a number, a name that is not a choice): its convention, which docs/reliability.md states —
# the command's usage, then one `aptkt <command>: error: ...` line, exit code 2.
USAGE_MISTAKES = [
    ["dataset", "generate", "-o", "x.h5", "-n", "many"],
    ["dataset", "info"],
    ["dataset"],
    ["collect", "--robot", "sim", "-o", "x.h5"],
    [
        "collect",
        "--robot",
        "sim",
        "--objects",
        "towel",
        "-n",
        "1",
        "-o",
        "x.h5",
        "--thermal-wait",
        "long",
    ],
    ["learn", "--robot", "mars", "--objects", "a,b"],
    ["prior", "build", "--frob"],
    ["reproduce", "fig99"],
    ["demo", "--budget", "1.5"],
    ["skin", "monitor", "--no-such-option"],
]


@pytest.mark.parametrize("argv", USAGE_MISTAKES, ids=lambda v: " ".join(v)[:50])
def test_usage_errors_exit_2_with_the_usage(capsys, argv):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    label = _label(argv) if len(argv) > 1 and not argv[1].startswith("-") else f"aptkt {argv[0]}"
    assert lines[0].startswith(f"usage: {label}"), err
    assert re.match(rf"^{re.escape(label)}: error: ", lines[-1]), lines[-1]
    assert sum(": error: " in line for line in lines) == 1


@pytest.mark.parametrize(
    "argv",
    [
        ["dataset", "generate", "-o", "{d}/x.h5", "--objects-file", "/dev/zero", "-n", "1"],
        ["collect", "--robot", "sim", "--objects-file", "/dev/zero", "--objects", "hard_box"]
        + ["-n", "1", "-o", "{d}/c.h5"],
    ],
    ids=["dataset generate", "collect --robot sim"],
)
def test_an_objects_file_that_is_a_device_is_one_line_not_a_hang(tmp_path, capsys, argv):
    """/dev/zero never ends: read as an object library it held the command for ever."""
    from aptkt.cli import main

    code = main([a.format(d=tmp_path) for a in argv])
    err = capsys.readouterr().err.strip()
    assert code == 1 and "\n" not in err, err
    assert "--objects-file /dev/zero: is a character device, not a regular file" in err


def test_a_live_run_refuses_a_library_of_another_sensors_features(tmp_path, capsys):
    """A library built from a feature table of other columns, given to a live run: one line
    naming the table (it failed in a transform with a shape mismatch, a traceback)."""
    from aptkt.cli import main

    lines = ["object,action,trial,force.0,thermal.0"]
    lines += [f"o{o},P1,{t},{o + 0.1 * t},{-o + 0.2 * t}" for o in range(3) for t in range(4)]
    (tmp_path / "t.csv").write_text("\n".join(lines) + "\n")
    lib = tmp_path / "lib.npz"
    assert main(["prior", "build", str(tmp_path / "t.csv"), "-o", str(lib), "-j", "1"]) == 0
    capsys.readouterr()
    argv = ["learn", "--robot", "sim", "--prior", str(lib), "--objects", "hard_box,towel"]
    assert main([*argv, "--budget", "1", "-o", str(tmp_path / "run")]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "hold features of another sensor or extraction" in err, err
    assert "t.csv)" in err and not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    "command, stray",
    [("learn", "report.md"), ("learn", "learning_curves.png"), ("recognise", "confusion.svg")]
    + [("benchmark", "benchmark.png"), ("benchmark", "lifelong.svg")],
)
def test_any_file_a_command_writes_is_an_earlier_result(tmp_path, capsys, command, stray):
    """Only the main results were checked: a report or plot already in -o (a user's own
    report.md, say) was replaced without --force."""
    from aptkt.cli import main

    lines = ["object,action,trial,force.0,thermal.0"]
    lines += [
        f"o{o},P1,{t},{o + 0.1 * (t % 3)},{-o + 0.2 * (t % 2)}" for o in range(9) for t in range(4)
    ]
    table = tmp_path / "t.csv"
    table.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / stray).write_text("mine")
    if command == "learn":
        argv = ["learn", str(table), "--prior-objects", "o0,o1", "--objects", "o2,o3"]
    elif command == "recognise":
        lib = tmp_path / "lib.npz"
        assert main(["prior", "build", str(table), "-o", str(lib), "-j", "1"]) == 0
        argv = ["recognise", "--prior", str(lib), str(table)]
    else:
        argv = ["benchmark", str(table), "--groups", "2", "-j", "1"]
    capsys.readouterr()
    assert main([*argv, "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--force" in err, err
    assert (out / stray).read_text() == "mine"
