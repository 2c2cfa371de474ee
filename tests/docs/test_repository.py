"""The repository stands on its own: README and docs/ point only at files inside it, every
relative link and path they name exists, and the citation and licence files agree with the
package metadata."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - the package depends on tomli there
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
DOCS = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
TOP = {p.name for p in ROOT.iterdir() if not p.name.startswith(".git")}

#: Pointers to things that exist only on the machine the project was written on.
OUTSIDE = re.compile(r"\.\./shared|DESIGN\.md|skin-protocol\.md|/work/|/home/|/Users/|[A-Z]:\\\\")
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
CODE = re.compile(r"`([^`\s]+)`")


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(md: Path) -> set[str]:
    return {_slug(m) for m in re.findall(r"^#+ (.+)$", md.read_text(), flags=re.MULTILINE)}


def _inside(path: Path) -> bool:
    return path.resolve().is_relative_to(ROOT)


def _prose(md: Path) -> str:
    return md.read_text(encoding="utf-8")


@pytest.mark.parametrize("md", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_pointer_outside_the_repository(md):
    for n, line in enumerate(_prose(md).splitlines(), 1):
        assert not OUTSIDE.search(line), f"{md.name}:{n} points outside the repository: {line}"


def test_no_pointer_outside_the_repository_in_code_or_build_files():
    files = [ROOT / "Makefile", ROOT / "pyproject.toml", ROOT / "Cargo.toml", ROOT / ".ci" / "run"]
    for folder, pattern in (("python", "*.py"), ("rust", "*.rs"), ("benches", "*.py")):
        files += (ROOT / folder).rglob(pattern)
    files += (ROOT / "benches").glob("*.md")
    for path in files:
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            assert not OUTSIDE.search(line), f"{path.relative_to(ROOT)}:{n}: {line}"


@pytest.mark.parametrize("md", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_relative_links_exist(md):
    for target in LINK.findall(_prose(md)):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        path = (md.parent / file) if file else md
        assert _inside(path), f"{md.name}: link {target} leaves the repository"
        assert path.exists(), f"{md.name}: link {target} names a missing file"
        if anchor and path.suffix == ".md":
            assert anchor in _anchors(path), f"{md.name}: link {target} names a missing heading"


@pytest.mark.parametrize("md", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_repository_paths_in_code_spans_exist(md):
    """`docs/gp.md`, `python/aptkt/experiments/`, ...: a code span whose first component is a
    top-level entry of the repository names a path that must exist."""
    for span in CODE.findall(_prose(md)):
        span = span.rstrip(".,:;")
        first = span.split("/", 1)[0]
        if "/" not in span or first not in TOP or any(c in span for c in "*<>{}"):
            continue
        # `tests/x.py::test_name` names a test: the file must exist and define it.
        file, _, test = span.partition("::")
        path = ROOT / file
        assert _inside(path) and path.exists(), f"{md.name}: `{span}` does not exist"
        if test:
            name = test.split("[", 1)[0]
            assert re.search(rf"^\s*(async\s+)?def {re.escape(name)}\(", path.read_text(), re.M), (
                f"{md.name}: `{span}` names a test that {file} does not define"
            )


def test_design_sections_cited_in_the_code_exist():
    cited = set()
    for src in [*(ROOT / "python").rglob("*.py"), *(ROOT / "rust").rglob("*.rs")]:
        cited |= {int(n) for n in re.findall(r"docs/design\.md §(\d+)", src.read_text())}
    sections = {
        int(n)
        for n in re.findall(r"^## (\d+)\. ", (ROOT / "docs/design.md").read_text(), re.MULTILINE)
    }
    assert cited and cited <= sections


def test_citation_and_licence_match_the_metadata():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    cargo = tomllib.loads((ROOT / "Cargo.toml").read_text())
    cff = (ROOT / "CITATION.cff").read_text()
    assert re.search(
        rf'^version: "{re.escape(cargo["workspace"]["package"]["version"])}"$', cff, re.MULTILINE
    )
    assert "doi: 10.3390/s18020634" in cff
    assert pyproject["project"]["license"] == "MIT"
    assert pyproject["project"]["license-files"] == ["LICENSE"]
    (author,) = pyproject["project"]["authors"]
    assert f'- name: "{author["name"]}"' in cff
    assert re.search(r"^license: MIT$", cff, re.MULTILINE)
    licence = (ROOT / "LICENSE").read_text()
    assert licence.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in licence


def test_ci_needs_nothing_outside_the_repository():
    script = (ROOT / ".ci" / "run").read_text()
    assert ".." not in script.replace('"$(dirname "$0")/.."', "")


def test_every_docs_page_named_in_code_or_docs_exists():
    """`docs/reproduce.md` in a help text, a docstring, a bench, a page or the changelog names a
    page that exists (pages move: the code and the changelog must follow)."""
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md", *(ROOT / "docs").rglob("*.md")]
    files += (ROOT / "benches").glob("*.md")
    for folder in ("python", "benches", "tests"):
        files += (ROOT / folder).rglob("*.py")
    for path in files:
        for page in re.findall(r"\bdocs/[\w/.-]+?\.md\b", path.read_text(encoding="utf-8")):
            assert (ROOT / page).is_file(), (
                f"{path.relative_to(ROOT)} names {page}, which does not exist"
            )


#: "issue 11", "Issues 11 and 15", "session 9's", "sessions 8-9": the project's internal
#: bookkeeping, which means nothing to a reader of the documentation or the code.
BOOKKEEPING = re.compile(r"\b(?:issues?|sessions?)\s+#?\d", re.IGNORECASE)


def _bookkeeping(text: str) -> list[str]:
    return [line for line in text.splitlines() if BOOKKEEPING.search(line)]


def test_no_issue_or_session_numbers_in_docs_or_code():
    files = [ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "benches").rglob("*")]
    files += (ROOT / "python").rglob("*.py")
    found = []
    for path in files:
        if path.is_file() and path.suffix in (".md", ".py", ".toml", ".txt"):
            text = path.read_text(encoding="utf-8")
            found += [f"{path.relative_to(ROOT)}: {line}" for line in _bookkeeping(text)]
    assert not found, "\n".join(found)


@pytest.mark.parametrize(
    "line,found",
    [
        ("the 30 s issue 15 asks for", True),
        ("(Issues 11 and 15, 2026-11-25)", True),
        ("### Session 9: the binding's thread pool", True),
        ("issue #12", True),
        ("sessions 8", True),
        ("a recording session (`aptkt.sim.drift`) and the issue it raises", False),
        ("session_id 3", False),
    ],
)
def test_the_bookkeeping_pattern(line, found):
    assert bool(_bookkeeping(line)) is found


def test_ci_builds_the_site_with_pinned_tools():
    """CI runs `make docs` between the static gates and the tests, and the site's tools are
    pinned exactly: a strict build must mean the same on every machine."""
    steps = [
        line for line in (ROOT / ".ci" / "run").read_text().splitlines() if line.startswith("make")
    ]
    assert steps == ["make lint", "make docs", "make test", "make release-check SDIST_INSTALL=no"]
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    tools = pyproject["dependency-groups"]["docs"]
    assert {re.split(r"[=<>!~\[]", t)[0] for t in tools} >= {
        "mkdocs",
        "mkdocs-material",
        "mkdocstrings-python",
    }
    assert all(re.fullmatch(r"[\w.\-\[\]]+==[\w.]+", t) for t in tools), tools
    makefile = (ROOT / "Makefile").read_text()
    assert "mkdocs build --strict" in makefile and "--group docs" in makefile


def test_the_paper_is_cited():
    for name in ("README.md", "docs/design.md", "docs/method.md"):
        text = (ROOT / name).read_text(encoding="utf-8")
        assert "10.3390/s18020634" in text and "Kaboli" in text, name
