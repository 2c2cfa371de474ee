"""The release check's own decisions, on auditwheel's words and made-up interpreters."""

from __future__ import annotations

import stat
import subprocess
import sys
from pathlib import Path

import pytest

# By its folder on the path, not as a package: a package tests/packaging would be imported as
# ``packaging`` and hide the library of that name from every test.
sys.path.insert(0, str(Path(__file__).parent))
from release_check import (  # noqa: E402
    ROOT,
    CheckFailed,
    check_manylinux,
    checked_pythons,
    find_python,
    main,
    manylinux_glibc,
    oldest_python,
    python_candidates,
    readme_example,
)

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

# auditwheel 6.8's report, wrapped as it prints it.
SHOWN = """
{wheel} is consistent with the following platform tag:
"{tag}".

The wheel references external versioned symbols in these
system-provided shared libraries: libc.so.6 with versions
{{'GLIBC_2.17'}}
"""


def test_the_packaging_library_is_not_hidden_by_this_folder():
    import packaging.version

    assert Path(packaging.version.__file__).parent.name == "packaging"
    assert not Path(packaging.version.__file__).is_relative_to(ROOT / "tests")


def test_manylinux_tags_name_their_glibc():
    assert manylinux_glibc("manylinux2014_x86_64") == (2, 17)
    assert manylinux_glibc("manylinux_2_17_aarch64") == (2, 17)
    assert manylinux_glibc("manylinux_2_35_x86_64") == (2, 35)
    assert manylinux_glibc("manylinux1_x86_64") == (2, 5)
    with pytest.raises(CheckFailed):
        manylinux_glibc("linux_x86_64")


def test_a_wheel_built_against_this_machines_glibc_is_refused():
    """The wheel `make wheel` built before it linked with zig: manylinux_2_35."""
    shown = SHOWN.format(
        wheel="aptkt-0.1.0-cp310-abi3-linux_x86_64.whl", tag="manylinux_2_35_x86_64"
    )
    with pytest.raises(CheckFailed, match=r"glibc 2\.35.*manylinux2014 allows glibc 2\.17"):
        check_manylinux(shown, "manylinux2014")


def test_a_manylinux2014_wheel_or_older_passes():
    for tag in ("manylinux_2_17_x86_64", "manylinux_2_12_x86_64", "manylinux2014_aarch64"):
        shown = SHOWN.format(wheel="aptkt.whl", tag=tag)
        assert check_manylinux(shown, "manylinux2014") == tag


def test_a_plain_linux_tag_or_no_tag_is_refused():
    with pytest.raises(CheckFailed, match="not manylinux"):
        check_manylinux(SHOWN.format(wheel="w.whl", tag="linux_x86_64"), "manylinux2014")
    with pytest.raises(CheckFailed, match="no platform tag"):
        check_manylinux("aptkt.whl is not a wheel", "manylinux2014")


def test_the_oldest_python_is_pyprojects_lower_bound():
    assert oldest_python(">=3.10") == "3.10"
    with pytest.raises(CheckFailed):
        oldest_python(">=3.10,<4")


def _fake_python(path: Path, version: str) -> str:
    path.write_text(f"#!/bin/sh\necho {version}\n")
    path.chmod(path.stat().st_mode | stat.S_IEXEC)
    return str(path)


def test_the_first_interpreter_of_the_right_version_is_used(tmp_path):
    wrong = _fake_python(tmp_path / "python-wrong", "3.11")
    right = _fake_python(tmp_path / "python-right", "3.10")
    missing = str(tmp_path / "absent")
    assert find_python("3.10", [missing, wrong, right]) == right


def test_no_interpreter_of_the_oldest_version_is_one_clear_error(tmp_path):
    wrong = _fake_python(tmp_path / "python3.10", "3.11")  # e.g. a pyenv shim of another version
    with pytest.raises(CheckFailed, match=r"no Python 3\.10 found.*APTKT_OLDEST_PYTHON"):
        find_python("3.10", [wrong], oldest=True)
    with pytest.raises(
        CheckFailed, match=r"no Python 3\.13 found \(the classifiers name it\).*APTKT_PYTHON_3_13"
    ):
        find_python("3.13", [wrong])


def test_every_python_the_classifiers_name_is_checked_from_the_oldest_allowed():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    versions = checked_pythons(project)
    assert versions[0] == oldest_python(project["requires-python"])
    assert versions == sorted(versions, key=lambda v: tuple(map(int, v.split("."))))
    named = {"requires-python": ">=3.10", "classifiers": []}
    for classifiers, ok in (
        (
            ["Programming Language :: Python :: 3.13", "Programming Language :: Python :: 3.10"],
            True,
        ),
        (["Programming Language :: Python :: 3.11"], False),  # 3.10 allowed, never checked
        (["Programming Language :: Python :: 3 :: Only"], False),
    ):
        named["classifiers"] = classifiers
        if ok:
            assert checked_pythons(named) == ["3.10", "3.13"]
        else:
            with pytest.raises(CheckFailed, match="the oldest must be named and checked"):
                checked_pythons(named)


def test_an_interpreter_can_be_named_per_version(tmp_path, monkeypatch):
    chosen = _fake_python(tmp_path / "py", "3.13")
    monkeypatch.setenv("APTKT_PYTHON_3_13", chosen)
    assert python_candidates("3.13")[0] == chosen
    assert find_python("3.13", python_candidates("3.13")) == chosen


def test_readme_example_and_its_output_are_found():
    code, printed = readme_example((ROOT / "README.md").read_text())
    assert "APTKT(" in code and "print(" in code
    assert printed.splitlines()[0].startswith("APTKT:")


def test_a_missing_archive_is_one_error_line(tmp_path, capsys):
    status = main(["--wheel", str(tmp_path / "none.whl"), "--sdist", str(tmp_path / "none.tgz")])
    err = capsys.readouterr().err
    assert status == 1
    assert err.splitlines() == [f"release-check: error: {tmp_path / 'none.whl'}: no such file"]


def test_runs_as_a_script(tmp_path):
    """`make release-check` runs the file directly, outside the tests package."""
    script = ROOT / "tests" / "packaging" / "release_check.py"
    out = subprocess.run(
        [sys.executable, str(script), "--wheel", "none.whl", "--sdist", "none.tar.gz"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=False,
    )
    assert out.returncode == 1
    assert out.stderr.splitlines() == ["release-check: error: none.whl: no such file"]
