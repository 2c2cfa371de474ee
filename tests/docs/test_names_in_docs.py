"""What the docs name in the code exists: every `aptkt.module.name` in a code span imports,
every `LearnerConfig.field` and `GPSettings.field` is a field, and the file formats the docs
name are the ones the code writes."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

from aptkt.data.schema import SCHEMA
from aptkt.gp.persistence import _SAVE_FORMAT
from aptkt.learning.config import GPSettings, LearnerConfig
from aptkt.learning.prior_file import FORMAT

ROOT = Path(__file__).resolve().parents[2]
#: The research log records names as they were.
DOCS = [
    p
    for p in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    if p.name != "research-log.md"
]
SPAN = re.compile(r"`([^`]+)`")
DOTTED = re.compile(r"(?<![\w./])(aptkt(?:\.[A-Za-z_]\w*)+)(/\d+)?")
SETTINGS = {"LearnerConfig": LearnerConfig, "GPSettings": GPSettings}
FIELD = re.compile(r"\b(LearnerConfig|GPSettings)\.(\w+)")
#: Names that are formats, not modules; each is checked against the code that writes it.
FORMATS = {SCHEMA, _SAVE_FORMAT.split("/")[0], FORMAT.split("/")[0]}


def resolves(dotted: str) -> bool:
    """``aptkt.learning.PriorKnowledge.recognise``: the longest importable module, then
    attributes."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for name in parts[i:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


def _spans(md: Path):
    for n, line in enumerate(md.read_text(encoding="utf-8").splitlines(), 1):
        for span in SPAN.findall(line):
            yield n, span


@pytest.mark.parametrize("md", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_dotted_name_in_the_docs_exists(md):
    missing = []
    for n, span in _spans(md):
        for m in DOTTED.finditer(span):
            name = m.group(1)
            if name in FORMATS or (m.group(2) and f"{name}{m.group(2)}" in {_SAVE_FORMAT, FORMAT}):
                continue
            if not resolves(name):
                missing.append(f"{md.relative_to(ROOT)}:{n}: {name}")
    assert not missing, "\n".join(missing)


@pytest.mark.parametrize("md", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_setting_in_the_docs_is_a_field(md):
    missing = [
        f"{md.relative_to(ROOT)}:{n}: {m.group(0)}"
        for n, span in _spans(md)
        for m in FIELD.finditer(span)
        if not hasattr(SETTINGS[m.group(1)], m.group(2))
    ]
    assert not missing, "\n".join(missing)


@pytest.mark.parametrize(
    ("name", "exists"),
    [
        ("aptkt.learning.PriorKnowledge.recognise", True),
        ("aptkt.learning.PriorKnowledge.no_such_method", False),
        ("aptkt.no_such_module", False),
        ("aptkt.sim.loopback", True),
    ],
)
def test_the_resolver(name, exists):
    assert resolves(name) is exists


def test_the_field_check_sees_a_removed_field():
    assert not hasattr(LearnerConfig, "relatedness") and FIELD.search("`LearnerConfig.relatedness`")
