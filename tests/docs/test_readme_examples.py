"""Every Python block of the README (and of docs/feature-tables.md) runs and prints what the
page says it prints.

A ```python block is followed by a ```text block with its expected output. Text must match
exactly; numbers may differ by 0.02 (the last printed digit, which BLAS or platform rounding can
move) — the README's claims are the numbers, so anything more is a failure.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
PAGES = (README, ROOT / "docs" / "feature-tables.md")
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)
NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
TOLERANCE = 0.02


def _examples(page: Path = README) -> list[tuple[str, str]]:
    blocks = FENCE.findall(page.read_text(encoding="utf-8"))
    pairs = []
    for k, (lang, body) in enumerate(blocks):
        if lang != "python":
            continue
        follows = blocks[k + 1] if k + 1 < len(blocks) else ("", "")
        assert follows[0] == "text", f"every python block in {page.name} needs its output after it"
        pairs.append((body, follows[1]))
    return pairs


EXAMPLES = _examples()
PAGE_EXAMPLES = [(page, *pair) for page in PAGES for pair in _examples(page)]


def test_the_readme_has_examples():
    assert len(EXAMPLES) >= 2


def _same(printed: str, expected: str) -> bool:
    if NUMBER.sub("#", printed.strip()) != NUMBER.sub("#", expected.strip()):
        return False
    got, want = NUMBER.findall(printed), NUMBER.findall(expected)
    return all(abs(float(a) - float(b)) <= TOLERANCE for a, b in zip(got, want))


@pytest.mark.parametrize(
    "page,code,expected",
    PAGE_EXAMPLES,
    ids=[f"{p.name}-block{k}" for k, (p, _, _) in enumerate(PAGE_EXAMPLES)],
)
def test_readme_block_prints_what_the_readme_says(page, code, expected):
    # A fresh interpreter per block, as a reader pasting it would run it.
    run = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False
    )
    assert run.returncode == 0, run.stderr
    assert _same(run.stdout, expected), (
        f"{page.name} says:\n{expected}\nbut the block printed:\n{run.stdout}"
    )


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
