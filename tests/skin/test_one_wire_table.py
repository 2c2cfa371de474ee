"""The wire's scales and ranges have one home: the table of the Rust skin crate
(``rust/skin/src/sensor.rs``), which the Python package and the simulator read. A second
definition — a force scale of 1/1024 written into the simulator's force loop, a 12-bit range
as 4095 in a check — fails here with the file and line.

The scan reads numbers as the languages read them (Python's tokenizer; Rust literals with
comments, strings and test modules left out) and looks for the values of the table that are
rare enough elsewhere to be a definition when they appear: the force scale and its field's
largest value, the largest cell id, the LM71's largest raw value and scale, and the
proximity's and acceleration's scales.
"""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TABLE = ROOT / "rust" / "skin" / "src" / "sensor.rs"

#: Value -> what it is on the wire.
WIRE_FACTS: dict[float, str] = {
    1024.0: "the force scale (raw / 1024)",
    1.0 / 1024.0: "the force scale (raw / 1024)",
    4095.0: "the force field's largest value (12 bits)",
    16383.0: "the largest cell id (14 bits)",
    8191.0: "the LM71's largest raw value (14 bits, signed)",
    0.03125: "the LM71's scale (°C per raw unit)",
    1.0 / 256.0: "the acceleration scale (g per raw unit)",
    1.0 / 65536.0: "the proximity scale",
}
#: As a float only: as integers they are common sizes.
FLOAT_ONLY = {
    256.0: "the acceleration scale (g per raw unit)",
    65536.0: "the proximity scale",
}

_RUST_NUMBER = re.compile(
    r"(?<![\w.])(0x[0-9A-Fa-f_]+|\d[\d_]*(?:\.\d[\d_]*)?(?:[eE][+-]?\d+)?)(?:_?[iuf](?:8|16|32|64|128|size))?(?![\w.])"
)
_RUST_STRING = re.compile(r'"(?:\\.|[^"\\])*"')


def _fact(text: str) -> str | None:
    digits = text.replace("_", "").lower()
    integer = digits.startswith(("0x", "0o", "0b"))  # (a file mode, 0o644, is an integer too)
    value = float(int(digits, 0)) if integer else float(digits)
    floating = not integer and ("." in digits or "e" in digits)
    return WIRE_FACTS.get(value) or (FLOAT_ONLY.get(value) if floating else None)


def rust_facts(path: Path) -> list[tuple[int, str, str]]:
    """``(line, literal, fact)`` of the wire's values among a Rust file's number literals,
    outside comments, strings and its test module."""
    source = path.read_text(encoding="utf-8").split("#[cfg(test)]")[0]
    found = []
    for n, line in enumerate(source.splitlines(), 1):
        code = _RUST_STRING.sub('""', line).split("//")[0]
        for m in _RUST_NUMBER.finditer(code):
            fact = _fact(m.group(1))
            if fact:
                found.append((n, m.group(1), fact))
    return found


def python_facts(path: Path) -> list[tuple[int, str, str]]:
    """``(line, literal, fact)`` of the wire's values among a Python file's number tokens."""
    found = []
    source = path.read_text(encoding="utf-8")
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.NUMBER and not tok.string.lower().endswith("j"):
            fact = _fact(tok.string)
            if fact:
                found.append((tok.start[0], tok.string, fact))
    return found


def _sources() -> list[Path]:
    rust = [
        p
        for p in sorted((ROOT / "rust").glob("*/src/**/*.rs"))
        if p != TABLE and "target" not in p.parts
    ]
    return rust + sorted((ROOT / "python" / "aptkt").rglob("*.py"))


def test_the_scan_finds_the_table_itself():
    # The scan is no scan if it misses the definitions it looks for.
    found = {fact for _, _, fact in rust_facts(TABLE)}
    assert {
        "the force scale (raw / 1024)",
        "the force field's largest value (12 bits)",
        "the largest cell id (14 bits)",
        "the LM71's largest raw value (14 bits, signed)",
        "the LM71's scale (°C per raw unit)",
        "the acceleration scale (g per raw unit)",
        "the proximity scale",
    } == found


@pytest.mark.parametrize(
    ("language", "source", "expected"),
    [
        ("rust", "let raw = (x * 1024.0).round().clamp(0.0, 4095.0);\n", ["1024.0", "4095.0"]),
        ("rust", "let f = raw as f64 * (1.0 / 1_024.0); // 4095\n", ["1_024.0"]),
        ("rust", 'const M: i32 = 4 << 20; let s = "0..=4095";\n', []),
        ("python", "_MAX = 0x3FFF\nscale = 0.03125\nn = 65536 + 256\n", ["0x3FFF", "0.03125"]),
        ("python", '"""raw / 1024"""\nx = y / 65536.0  # 4095\n', ["65536.0"]),
    ],
)
def test_the_scan_reads_numbers_as_the_language_does(tmp_path, language, source, expected):
    path = tmp_path / ("probe.rs" if language == "rust" else "probe.py")
    path.write_text(source)
    found = rust_facts(path) if language == "rust" else python_facts(path)
    assert [literal for _, literal, _ in found] == expected


def test_no_second_definition_of_a_wire_scale_or_range():
    second = []
    for path in _sources():
        found = rust_facts(path) if path.suffix == ".rs" else python_facts(path)
        second += [f"{path.relative_to(ROOT)}:{n}: {lit} ({fact})" for n, lit, fact in found]
    assert not second, (
        "the wire's scales and ranges belong to rust/skin/src/sensor.rs (read them from "
        "aptkt_skin::scale / RANGE_* or aptkt.skin.protocol.SCALE / RAW_RANGES):\n"
        + "\n".join(second)
    )
