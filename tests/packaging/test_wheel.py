"""The package as users install it: the abi3 wheel in a fresh virtual environment, with no
source tree on the path.

Marked ``release``: ``make release-check`` runs these on the wheel it built (``APTKT_WHEEL``);
``make test`` leaves them out, since the wheel is a second full Rust build (zig). Run alone
without ``APTKT_WHEEL``, the test runs ``make wheel`` (the pinned maturin and zig, into dist/).

The fresh environment gets the wheel without dependencies; numpy, h5py, ... come from the
environment running the tests through a path entry (not its ``.pth`` files, so an editable
install of aptkt there stays invisible). The test then checks that aptkt and its extension are
imported from the fresh environment and nowhere else.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import sysconfig
import venv
import zipfile
from email.parser import Parser
from pathlib import Path

import numpy as np
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]


# By its folder on the path (tests/packaging is no package: it would hide the library
# ``packaging``).
sys.path.insert(0, str(Path(__file__).parent))
from release_check import manylinux_glibc  # noqa: E402

# The one place the version is written.
VERSION = tomllib.loads((ROOT / "Cargo.toml").read_text())["workspace"]["package"]["version"]

pytestmark = [pytest.mark.slow, pytest.mark.release]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    given = os.environ.get("APTKT_WHEEL")
    if given:
        path = Path(given)
        assert path.is_file(), f"APTKT_WHEEL={given} is not a file"
        return path
    subprocess.run(["make", "wheel"], cwd=ROOT, check=True, capture_output=True)
    (path,) = (ROOT / "dist").glob(f"aptkt-*_{platform.machine()}.whl")
    return path


def _dist_info(wheel: Path, name: str) -> str:
    with zipfile.ZipFile(wheel) as archive:
        (member,) = [n for n in archive.namelist() if n.endswith(f".dist-info/{name}")]
        return archive.read(member).decode()


@pytest.fixture(scope="module")
def fresh(wheel, tmp_path_factory) -> Path:
    """A new virtual environment holding only the installed wheel (and its bin/aptkt)."""
    env = tmp_path_factory.mktemp("venv")
    venv.create(env, with_pip=False)
    python = env / "bin" / "python"
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet"]
        + ["--no-deps", "--no-index", str(wheel)],
        check=True,
        capture_output=True,
        text=True,
    )
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    # The dependencies: this interpreter's site-packages, appended after the fresh one's.
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (Path(site) / "_aptkt_test_deps.pth").write_text("\n".join(sorted(deps)) + "\n")
    return env


def _run(env: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    clean["MPLBACKEND"] = "Agg"
    return subprocess.run(
        list(args), cwd=cwd, env=clean, capture_output=True, text=True, timeout=600, check=False
    )


def test_the_wheel_is_abi3_and_holds_the_extension_and_data(wheel):
    assert "-abi3-" in wheel.name
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "aptkt/_core.abi3.so" in names or "aptkt/_core.pyd" in names
    for data in ("aptkt/sim/objects.toml", "aptkt/skin/data/patch_7cells.toml", "aptkt/py.typed"):
        assert data in names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)


def test_the_wheel_runs_on_glibc_2_17(wheel):
    """manylinux2014: every platform tag of the wheel asks for glibc 2.17 or older."""
    tags = Parser().parsestr(_dist_info(wheel, "WHEEL")).get_all("Tag")
    assert tags
    for tag in tags:
        python, abi, plat = tag.split("-")
        assert (python, abi) == ("cp310", "abi3")
        assert manylinux_glibc(plat) <= (2, 17), tag


def test_the_wheel_carries_the_workspace_version_and_metadata(wheel):
    meta = Parser().parsestr(_dist_info(wheel, "METADATA"))
    assert meta["Version"] == VERSION
    assert wheel.name.startswith(f"aptkt-{VERSION}-")
    assert meta["Requires-Python"] == ">=3.10"
    assert meta["License-Expression"] == "MIT"
    assert "Paper, https://doi.org/10.3390/s18020634" in meta.get_all("Project-URL")


def test_installed_wheel_runs_without_the_source_tree(fresh, tmp_path):
    out = _run(fresh, str(fresh / "bin" / "aptkt"), "--version", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["aptkt", VERSION]
    versions = _run(
        fresh,
        str(fresh / "bin" / "python"),
        "-c",
        "import aptkt, aptkt._core, importlib.metadata as m;"
        "print(aptkt.__version__, aptkt._core.__version__, m.version('aptkt'))",
        cwd=tmp_path,
    )
    assert versions.returncode == 0, versions.stderr
    assert versions.stdout.split() == [VERSION] * 3

    where = _run(
        fresh,
        str(fresh / "bin" / "python"),
        "-c",
        "import aptkt, aptkt._core; print(aptkt.__file__); print(aptkt._core.__file__)",
        cwd=tmp_path,
    )
    assert where.returncode == 0, where.stderr
    for line in where.stdout.split():
        assert Path(line).resolve().is_relative_to(fresh.resolve()), line
        assert not Path(line).resolve().is_relative_to(ROOT), line


def test_installed_wheel_learns(fresh, tmp_path):
    """A small learning run from the installed package: APTKT with a related prior against the
    baseline on a synthetic two-action problem; both must learn something."""
    script = tmp_path / "learn.py"
    script.write_text(
        """
import numpy as np
from aptkt.learning import APTKT, LearnerConfig, Observations, PoolEnvironment, PriorKnowledge

rng = np.random.default_rng(0)
centres = {"old_a": 0.0, "old_b": 4.0, "new_a": 0.5, "new_b": 4.5}
def table(objects, n):
    objs = np.repeat(objects, n)
    force = np.array([[centres[o] + rng.normal()] for o in objs])
    return {"press": Observations.from_arrays("press", objs, force=force)}
prior = PriorKnowledge.build(table(["old_a", "old_b"], 8), seed=0)
pool, test = table(["new_a", "new_b"], 6), table(["new_a", "new_b"], 10)
for transfer in ("paper", "none"):
    cfg = LearnerConfig(transfer=transfer, budget=4, seed=0)
    run = APTKT(cfg, prior=prior if transfer != "none" else None).run(
        PoolEnvironment(pool, seed=0), ["press"], ["new_a", "new_b"], test=test)
    print(transfer, run.steps[-1].mean_accuracy)
"""
    )
    out = _run(fresh, str(fresh / "bin" / "python"), str(script), cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    results = dict(line.split() for line in out.stdout.splitlines())
    assert set(results) == {"paper", "none"}
    for accuracy in results.values():
        assert 0.75 <= float(accuracy) <= 1.0


def test_installed_command_line_learns_from_a_table(fresh, tmp_path):
    """``aptkt learn --table`` from the installed command: the demo's files for three methods."""
    lines = ["object,action,trial,force.0,thermal.0"]
    centres = {"old_a": 0.0, "old_b": 4.0, "new_a": 0.5, "new_b": 4.5}
    rng = np.random.default_rng(1)
    for obj, c in centres.items():
        for trial in range(4):
            force, heat = c + rng.normal(), -c + rng.normal()
            lines.append(f"{obj},press,{trial},{force!r},{heat!r}")
    (tmp_path / "features.csv").write_text("\n".join(lines) + "\n")
    out = _run(
        fresh,
        str(fresh / "bin" / "aptkt"),
        "learn",
        "--table",
        "features.csv",
        "--prior-objects",
        "old_a,old_b",
        "--objects",
        "new_a,new_b",
        "--budget",
        "2",
        "--runs",
        "1",
        "-o",
        "learned",
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    for name in ("results.csv", "summary.json", "learning_curves.png", "prior.npz"):
        assert (tmp_path / "learned" / name).is_file(), name
