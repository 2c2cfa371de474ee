"""The release as a lab installs it (``make release-check``).

1. ``auditwheel show``: the wheel must be manylinux2014 (glibc 2.17) or older, or whatever
   ``--manylinux`` names.
2. ``twine check --strict`` on the wheel and the sdist: the metadata PyPI renders.
3. A fresh virtual environment of every Python version pyproject.toml's classifiers name (the
   oldest of them must be requires-python's lower bound): the wheel installed with its
   dependencies from the package index, then ``aptkt --version`` against the workspace's
   version, the README's first example against the output the README prints, and ``aptkt
   learn --table`` on a generated table. So the classifiers claim the versions the wheel is
   checked on, and no other.
4. The sdist built from source into the oldest Python's environment (``pip install --no-deps
   --force-reinstall``) and step 3's checks again. Cargo builds it in a new, temporary
   directory, every crate from scratch: path crates get the same file names wherever their
   sources lie, and the sdist's files carry a fixed old date, so in a directory holding an
   earlier build (the checkout's target/, or a previous check's) cargo would take that build
   as up to date and link it instead of compiling the sdist's sources.

Each failure ends in one ``release-check: error: ...`` line and exit status 1.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]

# Legacy manylinux names and the glibc they stand for (PEP 599, PEP 571, PEP 513).
LEGACY_MANYLINUX = {"manylinux2014": (2, 17), "manylinux2010": (2, 12), "manylinux1": (2, 5)}


class CheckFailed(Exception):
    """One failed check, said in one line."""


def manylinux_glibc(tag: str) -> tuple[int, int]:
    """The glibc version a manylinux tag (legacy or PEP 600) requires, e.g. (2, 17)."""
    for name, glibc in LEGACY_MANYLINUX.items():
        if tag == name or tag.startswith(name + "_"):
            return glibc
    match = re.fullmatch(r"manylinux_(\d+)_(\d+)(?:_\w+)?", tag)
    if not match:
        raise CheckFailed(f"{tag!r} is not a manylinux tag")
    return int(match[1]), int(match[2])


def audited_tag(auditwheel_output: str) -> str:
    """The platform tag ``auditwheel show`` found the wheel consistent with."""
    text = " ".join(auditwheel_output.split())
    match = re.search(r'consistent with the following platform tag: "([^"]+)"', text)
    if not match:
        raise CheckFailed(f"auditwheel show reported no platform tag: {text[:300]}")
    return match[1]


def check_manylinux(auditwheel_output: str, allowed: str) -> str:
    tag = audited_tag(auditwheel_output)
    if not tag.startswith("manylinux"):
        raise CheckFailed(f"auditwheel: the wheel is {tag}, not manylinux")
    need, most = manylinux_glibc(tag), manylinux_glibc(allowed)
    if need > most:
        raise CheckFailed(
            f"auditwheel: the wheel is {tag} (glibc {need[0]}.{need[1]}); "
            f"{allowed} allows glibc {most[0]}.{most[1]} at most"
        )
    return tag


def oldest_python(requires_python: str) -> str:
    """'3.10' from '>=3.10' (the only form of lower bound this package uses)."""
    match = re.fullmatch(r"\s*>=\s*(\d+)\.(\d+)\s*", requires_python)
    if not match:
        raise CheckFailed(f"requires-python {requires_python!r} is not of the form '>=X.Y'")
    return f"{match[1]}.{match[2]}"


def _version_key(version: str) -> tuple[int, ...]:
    return tuple(int(part) for part in version.split("."))


def checked_pythons(project: dict) -> list[str]:
    """The Python versions the classifiers name, oldest first; the oldest must be the lower
    bound of requires-python (a version it allows but the release never checked, or the
    reverse, would be a claim nobody tested)."""
    versions = sorted(
        {
            match[1]
            for classifier in project.get("classifiers", [])
            if (match := re.fullmatch(r"Programming Language :: Python :: (3\.\d+)", classifier))
        },
        key=_version_key,
    )
    oldest = oldest_python(project["requires-python"])
    if not versions or versions[0] != oldest:
        raise CheckFailed(
            f"the classifiers name Python {', '.join(versions) or 'no version'}, but "
            f"requires-python allows {oldest} and newer: the oldest must be named and checked"
        )
    return versions


def _python_version(executable: str) -> str | None:
    try:
        out = subprocess.run(
            [executable, "-c", "import sys; print('%d.%d' % sys.version_info[:2])"],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    except OSError:
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def python_variable(version: str) -> str:
    """The environment variable that names an interpreter of ``version`` (APTKT_PYTHON_3_13)."""
    return "APTKT_PYTHON_" + version.replace(".", "_")


def python_candidates(version: str, *, oldest: bool = False) -> list[str]:
    """Where an interpreter of ``version`` may live: $APTKT_PYTHON_3_X (for the oldest also
    $APTKT_OLDEST_PYTHON), the PATH, pyenv."""
    found = []
    for variable in (python_variable(version), "APTKT_OLDEST_PYTHON" if oldest else None):
        if variable and os.environ.get(variable):
            found.append(os.environ[variable])
    on_path = shutil.which(f"python{version}")
    if on_path:
        found.append(on_path)
    # A pyenv shim on the PATH fails unless the version is selected; pyenv itself knows where
    # every installed version lives.
    pyenv = shutil.which("pyenv")
    if pyenv:
        prefix = subprocess.run(
            [pyenv, "prefix", version], capture_output=True, text=True, check=False
        )
        if prefix.returncode == 0:
            found += [str(Path(p) / "bin" / f"python{version}") for p in prefix.stdout.split(":")]
    root = os.environ.get("PYENV_ROOT", str(Path.home() / ".pyenv"))
    found += sorted(glob.glob(f"{root}/versions/{version}.*/bin/python{version}"), reverse=True)
    found += [f"/usr/bin/python{version}", f"/usr/local/bin/python{version}"]
    return found


def find_python(version: str, candidates: list[str], *, oldest: bool = False) -> str:
    for candidate in candidates:
        if _python_version(candidate) == version:
            return candidate
    why = "the oldest that requires-python allows" if oldest else "the classifiers name it"
    variable = "APTKT_OLDEST_PYTHON" if oldest else python_variable(version)
    raise CheckFailed(
        f"no Python {version} found ({why}); install it (e.g. `pyenv install {version}`) or set "
        f"{variable} to its interpreter"
    )


def readme_example(readme: str) -> tuple[str, str]:
    """The README's first Python example that runs the learner, and the output it prints."""
    match = re.search(r"```python\n(.*?APTKT\(.*?)```\s*\n[^`]*```text\n(.*?)```", readme, re.S)
    if not match:
        raise CheckFailed("README.md has no Python example of the learner with its output")
    return match[1], match[2]


def _run(args: list[str], cwd: Path, env: dict[str, str] | None = None) -> str:
    out = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        last = (out.stderr.strip() or out.stdout.strip()).splitlines()[-1:] or ["(no output)"]
        raise CheckFailed(f"`{' '.join(args)}` exited with {out.returncode}: {last[0]}")
    return out.stdout


def _clean_env() -> dict[str, str]:
    """The environment without this checkout on the import path."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["MPLBACKEND"] = "Agg"
    return env


def _table(path: Path) -> None:
    """Two old and two new objects, one press each, far apart in both modalities."""
    rows = ["object,action,trial,force.0,thermal.0"]
    centres = {"old_a": 0.0, "old_b": 4.0, "new_a": 0.5, "new_b": 4.5}
    for i, (obj, c) in enumerate(centres.items()):
        for trial in range(4):
            wobble = ((7 * i + 3 * trial) % 5 - 2) / 4  # deterministic noise in [-0.5, 0.5]
            rows.append(f"{obj},press,{trial},{c + wobble},{-c - wobble / 2}")
    path.write_text("\n".join(rows) + "\n")


def check_installed(env: Path, version: str, work: Path) -> None:
    """What a user runs first, from an installed package and outside this checkout."""
    python, aptkt, clean = str(env / "bin" / "python"), str(env / "bin" / "aptkt"), _clean_env()
    said = _run([aptkt, "--version"], work, clean).split()
    if said != ["aptkt", version]:
        raise CheckFailed(f"aptkt --version says {' '.join(said)!r}, the workspace {version}")
    where = _run([python, "-c", "import aptkt._core as c; print(c.__file__)"], work, clean)
    if not Path(where.strip()).resolve().is_relative_to(env.resolve()):
        raise CheckFailed(f"aptkt's core was imported from {where.strip()}, not from {env}")

    code, printed = readme_example((ROOT / "README.md").read_text())
    (work / "example.py").write_text(code)
    got = _run([python, "example.py"], work, clean)
    if got != printed:
        raise CheckFailed(f"the README's example printed {got!r}; the README says {printed!r}")

    _table(work / "features.csv")
    learn = [aptkt, "learn", "--table", "features.csv", "--prior-objects", "old_a,old_b"]
    learn += ["--objects", "new_a,new_b", "--budget", "2", "--runs", "1", "-o", "learned"]
    _run(learn, work, clean)
    summary = json.loads((work / "learned" / "summary.json").read_text())
    final = summary["final_mean_accuracy"]
    if set(final) != {"APTKT", "APTKT+aux", "baseline"} or min(final.values()) < 0.75:
        raise CheckFailed(f"aptkt learn --table: final accuracies {final}, expected all >= 0.75")
    print(f"    aptkt {version}: README example as printed; learn --table final accuracy {final}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="release-check", description=__doc__.split("\n")[0])
    parser.add_argument("--wheel", type=Path, required=True)
    parser.add_argument("--sdist", type=Path, required=True)
    parser.add_argument("--manylinux", default="manylinux2014")
    parser.add_argument(
        "--no-sdist-install",
        action="store_true",
        help="check the sdist's metadata but do not build it (CI: a full Rust build)",
    )
    args = parser.parse_args(argv)
    try:
        for path in (args.wheel, args.sdist):
            if not path.is_file():
                raise CheckFailed(f"{path}: no such file")
        tools = Path(sys.executable).parent
        shown = _run([str(tools / "auditwheel"), "show", str(args.wheel)], ROOT)
        tag = check_manylinux(shown, args.manylinux)
        print(f"    auditwheel: {args.wheel.name} is {tag}")
        _run([str(tools / "twine"), "check", "--strict", str(args.wheel), str(args.sdist)], ROOT)
        print(f"    twine check: {args.wheel.name}, {args.sdist.name} pass")

        pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
        workspace = tomllib.loads((ROOT / "Cargo.toml").read_text())
        version = workspace["workspace"]["package"]["version"]
        versions = checked_pythons(pyproject["project"])
        # Every interpreter found before the first long installation.
        pythons = {
            v: find_python(v, python_candidates(v, oldest=i == 0), oldest=i == 0)
            for i, v in enumerate(versions)
        }
        for v, python in pythons.items():
            print(f"    Python {v}: {python}")

        with tempfile.TemporaryDirectory(prefix="aptkt-release-") as tmp:
            for v, python in pythons.items():
                env, work = Path(tmp) / f"venv-{v}", Path(tmp) / f"work-{v}"
                _run([python, "-m", "venv", str(env)], ROOT)
                pip = [str(env / "bin" / "python"), "-m", "pip", "install", "--quiet"]
                pip += ["--disable-pip-version-check"]
                start = time.monotonic()
                _run(pip + [str(args.wheel.resolve())], ROOT, _clean_env())
                took = time.monotonic() - start
                print(f"    Python {v}: wheel installed with its dependencies ({took:.0f} s)")
                work.mkdir()
                check_installed(env, version, work)
            # The sdist goes into the oldest Python's environment.
            oldest = versions[0]
            env, work = Path(tmp) / f"venv-{oldest}", Path(tmp) / f"work-{oldest}"
            pip = [str(env / "bin" / "python"), "-m", "pip", "install", "--quiet"]
            pip += ["--disable-pip-version-check"]

            if args.no_sdist_install:
                print("    sdist: not built (--no-sdist-install)")
                print("release-check: passed")
                return 0
            build = _clean_env() | {"CARGO_TARGET_DIR": str(Path(tmp) / "cargo")}
            start = time.monotonic()
            _run(pip + ["--no-deps", "--force-reinstall", str(args.sdist.resolve())], ROOT, build)
            origin = glob.glob(str(env / "lib" / "python*" / "site-packages" / "aptkt-*.dist-info"))
            url = json.loads((Path(origin[0]) / "direct_url.json").read_text())["url"]
            if not url.endswith(args.sdist.name):
                raise CheckFailed(f"the environment's aptkt came from {url}, not the sdist")
            print(f"    sdist built and installed ({time.monotonic() - start:.0f} s)")
            shutil.rmtree(work)
            work.mkdir()
            check_installed(env, version, work)
    except CheckFailed as error:
        print(f"release-check: error: {error}", file=sys.stderr)
        return 1
    print("release-check: passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
