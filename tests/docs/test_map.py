"""README's "What is where" is the map of the tree: it names every crate under ``rust/`` and
every folder of the Python package, and every folder it names exists."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "python" / "aptkt"


def what_is_where(readme: str) -> str:
    """The code block of README's "What is where" section."""
    section = readme.split("## What is where", 1)[1].split("\n## ", 1)[0]
    return section.split("```", 2)[1]


def crates() -> set[str]:
    return {p.parent.name for p in (ROOT / "rust").glob("*/Cargo.toml")}


def package_folders() -> set[str]:
    """Folders of the package holding code or data, relative to it (``sim/loopback``)."""
    return {
        p.relative_to(PACKAGE).as_posix()
        for p in PACKAGE.rglob("*")
        if p.is_dir() and p.name != "__pycache__" and any(p.iterdir())
    }


def named_crates(block: str) -> set[str]:
    return set(re.findall(r"(?<![\w/])rust/([\w-]+)", block))


def named_folders(block: str) -> set[str]:
    """The package's folders the map names: ``name/`` entries at the start of its lines
    (after ``python/aptkt/``), and ``name/`` mentioned in an entry's first column."""
    package = block.split("python/aptkt/", 1)[1].split("\ntests/", 1)[0]
    folders = set()
    for line in package.splitlines():
        head = line[:30]  # the entries' column; the rest describes them
        folders |= {m.rstrip("/") for m in re.findall(r"(?<![\w/.])[\w]+(?:/[\w]+)*/", head)}
    return folders


def test_the_map_names_every_crate_and_every_package_folder():
    block = what_is_where((ROOT / "README.md").read_text(encoding="utf-8"))
    assert sorted(crates() - named_crates(block)) == [], "crates missing from README's map"
    missing = sorted(package_folders() - named_folders(block))
    assert missing == [], f"folders of python/aptkt missing from README's map: {missing}"


def test_every_folder_the_map_names_exists():
    block = what_is_where((ROOT / "README.md").read_text(encoding="utf-8"))
    assert sorted(named_crates(block) - crates()) == []
    assert sorted(named_folders(block) - package_folders()) == []


def test_the_map_reader_finds_what_a_line_names():
    # The reader itself: a map that named nothing would pass the tests above vacuously.
    block = (
        "rust/core      the core\n"
        "python/aptkt/  the package\n"
        "  sim/         the world (not data/, which is described here)\n"
        "  sim/loopback/  its controller\n"
        "  commands/, cli.py  the command line\n"
        "tests/         tests\n"
    )
    assert named_crates(block) == {"core"}
    assert named_folders(block) == {"sim", "sim/loopback", "commands"}
