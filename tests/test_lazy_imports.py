"""The command line starts without the heavy libraries (scikit-learn and SciPy take from half a
second to two to import, the more so on a busy machine), and the packages that load their names
on first use offer the same objects as their modules."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys

import pytest

from aptkt._lazy import _type_checking_imports

HEAVY = ("sklearn", "scipy", "matplotlib", "pandas", "aptkt.gp.estimator")

_PROBE = """
import json, sys
from aptkt.cli import main
for argv in {argvs!r}:
    try:
        main(argv)
    except SystemExit:
        pass
print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)))
"""


@pytest.mark.parametrize(
    "argvs",
    [
        [["--help"]],
        [["dataset", "generate", "--help"], ["learn", "--help"], ["benchmark", "--help"]],
        [["prior", "build", "--help"], ["recognise", "--help"], ["demo", "--help"]],
    ],
    ids=["top", "dataset-learn-benchmark", "prior-recognise-demo"],
)
def test_the_command_line_parses_without_the_heavy_libraries(argvs) -> None:
    probe = _PROBE.format(argvs=argvs, heavy=HEAVY)
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True
    ).stdout
    assert json.loads(out.splitlines()[-1]) == []


@pytest.mark.parametrize("package", ["aptkt.learning", "aptkt.gp"])
def test_every_exported_name_is_its_modules_object(package) -> None:
    pkg = importlib.import_module(package)
    exports = _type_checking_imports(pkg.__file__)
    assert sorted(exports) == sorted(pkg.__all__)
    for name, module in exports.items():
        assert getattr(pkg, name) is getattr(importlib.import_module(module), name)
        assert name in dir(pkg)
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        _ = pkg.no_such_name


def test_a_bad_table_or_a_missing_library_is_refused_before_the_heavy_libraries(tmp_path) -> None:
    """A mistake in the input is one line in a fraction of a second: the learner's modules
    (scikit-learn, SciPy) load only once the arguments and the files have been checked, and
    the table holds enough objects for what was asked."""
    bad = tmp_path / "touches.csv"
    bad.write_text("object,action,trial,force.0\na,P,1,x\n")
    good = tmp_path / "good.csv"
    good.write_text("object,action,trial,force.0\na,P,1,0.5\n")
    out = tmp_path / "out"
    argvs = [
        ["benchmark", str(bad), "-o", str(out)],
        ["benchmark", "--recognition", str(bad), "-o", str(out)],
        ["prior", "build", str(bad), "-o", str(tmp_path / "lib.npz")],
        ["recognise", "--prior", str(tmp_path / "lib.npz"), str(bad), "-o", str(out)],
        ["recognise", "--prior", str(tmp_path / "missing.npz"), str(good), "-o", str(out)],
        # too few objects for the groups, the draws or the batches asked for
        ["benchmark", str(good), "-o", str(out)],
        ["benchmark", "--recognition", str(good), "-o", str(out)],
        ["benchmark", "--lifelong", str(good), "-o", str(out)],
    ]
    for argv in argvs:
        probe = _PROBE.format(argvs=[argv], heavy=HEAVY)
        done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        assert done.stderr.count("\n") == 1 and ": error: " in done.stderr, (argv, done.stderr)
        assert json.loads(done.stdout.splitlines()[-1]) == [], argv
