"""Every Python block of the README and of the documentation site (docs/) runs, and prints what
the page says it prints.

A ```python block followed by a ```text block (the next fenced block of the page) prints that
text. Text must match exactly; each number may differ from the printed one by two units of its
last printed digit, and never by more than 0.02 (BLAS or platform rounding can move the last
digit) — the pages' claims are the numbers, so anything more is a failure. In the README every
Python block has its output after it. Blocks that need a robot run against the loopback
controller and its simulated skin, as the page says.
"""

from __future__ import annotations

import ast
import builtins
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)
NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
#: λ as the examples print it and the prose quotes it.
LAMBDA = re.compile(r"(?:λ|lambda)\s*=?\s*(\d+(?:\.\d+)?)")
TOLERANCE = 0.02


def _blocks(md: Path) -> list[tuple[str, str, int, int]]:
    """(language, body, start, end) of every fenced block of a page, in order."""
    text = md.read_text(encoding="utf-8")
    return [(m[1], m[2], m.start(), m.end()) for m in FENCE.finditer(text)]


def _examples(md: Path) -> list[tuple[str, str | None]]:
    """(code, expected output or None) of every Python block of a page."""
    blocks = _blocks(md)
    pairs = []
    for k, (lang, body, _, _) in enumerate(blocks):
        if lang != "python":
            continue
        follows = blocks[k + 1] if k + 1 < len(blocks) else None
        expected = follows[1] if follows is not None and follows[0] == "text" else None
        if md == README:
            assert expected is not None, "every python block in README.md needs its output after it"
        pairs.append((body, expected))
    return pairs


EXAMPLES = [(md, code, out) for md in PAGES for code, out in _examples(md)]
IDS = [f"{md.relative_to(ROOT).as_posix()}-{k}" for k, (md, _, _) in enumerate(EXAMPLES)]


def test_the_pages_have_examples():
    assert sum(md == README for md, _, _ in EXAMPLES) >= 2
    assert sum(md != README for md, _, _ in EXAMPLES) >= 2


def _tolerance(expected: str) -> float:
    """Two units of the number's last printed digit, at most TOLERANCE."""
    decimals = len(expected.partition(".")[2].split("e")[0].split("E")[0])
    return min(TOLERANCE, 2 * 10.0**-decimals)


def _same(printed: str, expected: str) -> bool:
    if NUMBER.sub("#", printed.strip()) != NUMBER.sub("#", expected.strip()):
        return False
    got, want = NUMBER.findall(printed), NUMBER.findall(expected)
    return all(abs(float(a) - float(b)) <= _tolerance(b) + 1e-12 for a, b in zip(got, want))


def _undefined_names(code: str) -> set[str]:
    """Names a block reads but never binds (imports, assignments, definitions, arguments):
    what a reader pasting the block would meet as a NameError, found without running it."""
    tree = ast.parse(code)
    bound: set[str] = set(dir(builtins))
    loaded: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            (loaded if isinstance(node.ctx, ast.Load) else bound).add(node.id)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            bound |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, ast.arg):
            bound.add(node.arg)
        elif isinstance(node, ast.ExceptHandler) and node.name:
            bound.add(node.name)
    return loaded - bound


@pytest.mark.parametrize("md,code,expected", EXAMPLES, ids=IDS)
def test_every_name_a_block_uses_is_imported_or_defined(md, code, expected):
    missing = _undefined_names(code)
    assert not missing, f"{md.name}: the block uses {sorted(missing)} without importing them"


@pytest.mark.parametrize("md,code,expected", EXAMPLES, ids=IDS)
def test_the_block_runs_and_prints_what_the_page_says(md, code, expected, tmp_path):
    if "Loopback(" in code:
        # A reader's machine has 127.0.0.1's UR ports free; a busy test machine may not (other
        # test runs' loopbacks): the block gets a free loopback address, as the suite's do.
        from loopback_helpers import free_loopback_host

        code = code.replace('"127.0.0.1"', f'"{free_loopback_host()}"')
    # A fresh interpreter per block in an empty directory, as a reader pasting it would run it.
    run = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=tmp_path,
    )
    assert run.returncode == 0, f"{md.name}:\n{run.stderr}"
    if expected is not None:
        assert _same(run.stdout, expected), (
            f"{md.name} says:\n{expected}\nbut the block printed:\n{run.stdout}"
        )


def _prose_after_outputs(md: Path) -> list[tuple[str, str]]:
    """(printed output, the prose after it up to the next block or heading) of every Python
    block's output on a page."""
    text = md.read_text(encoding="utf-8")
    blocks = _blocks(md)
    pairs = []
    for k in range(1, len(blocks)):
        if blocks[k][0] == "text" and blocks[k - 1][0] == "python":
            end = blocks[k + 1][2] if k + 1 < len(blocks) else len(text)
            prose = text[blocks[k][3] : end]
            heading = re.search(r"^#", prose, re.MULTILINE)
            pairs.append((blocks[k][1], prose[: heading.start()] if heading else prose))
    return pairs


def _lambdas_disagree(output: str, prose: str) -> list[str]:
    """The λ values the prose quotes that the output does not print, digit for digit."""
    printed = set(LAMBDA.findall(output))
    return [v for v in LAMBDA.findall(prose) if v not in printed]


@pytest.mark.parametrize("md", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_the_prose_quotes_lambda_as_the_example_prints_it(md):
    for output, prose in _prose_after_outputs(md):
        assert not _lambdas_disagree(output, prose), (
            f"{md.name}: the text quotes λ {_lambdas_disagree(output, prose)}, the example prints\n"
            f"{output}"
        )


def test_a_lambda_rounded_in_the_prose_is_caught():
    output = "box: transfers from cardboard (λ 0.675, log BF 3.4)\n"
    assert _lambdas_disagree(output, "so the box learns from the cardboard with λ 0.67.") == [
        "0.67"
    ]
    assert _lambdas_disagree(output, "so the box learns from the cardboard with λ 0.675.") == []


@pytest.mark.parametrize(
    "printed,ok",
    [
        ("accuracy 0.78, 0.83", True),
        ("accuracy 0.79, 0.82", True),
        ("accuracy 0.81, 0.83", False),
        ("accuracy 0.78", False),
        ("accuracy: 0.78, 0.83", False),
    ],
)
def test_the_comparison_is_strict(printed, ok):
    assert _same(printed, "accuracy 0.78, 0.83") is ok


@pytest.mark.parametrize(
    "printed,ok", [("λ 0.675", True), ("λ 0.677", True), ("λ 0.678", False), ("λ 0.67", False)]
)
def test_the_tolerance_is_two_units_of_the_last_printed_digit(printed, ok):
    assert _same(printed, "λ 0.675") is ok


def test_a_missing_import_is_found():
    assert _undefined_names("from aptkt.robot import UR10\nUR10.x(SerialSkin('p'))") == {
        "SerialSkin"
    }
    assert (
        _undefined_names("import numpy as np\nfor k in range(3):\n    print(np.ones(k))") == set()
    )
