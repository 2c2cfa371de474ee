"""docs/cli.md is the command line's own account of itself: regenerate it with
`python -m aptkt.reference > docs/cli.md` whenever an option changes."""

from __future__ import annotations

from pathlib import Path

from aptkt.cli import build_parser
from aptkt.reference import markdown_reference

ROOT = Path(__file__).resolve().parents[2]


def test_the_cli_reference_is_what_the_parsers_say():
    page = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    assert page == markdown_reference(build_parser()), (
        "docs/cli.md differs from the command line: run `python -m aptkt.reference > docs/cli.md`"
    )


def test_the_reference_names_every_command_and_option():
    page = markdown_reference(build_parser())
    for command in ("aptkt demo", "aptkt prior merge", "aptkt recognise", "aptkt benchmark"):
        assert f"`{command}`" in page
    for option in ("`--priors`", "`--merge-into`", "`--false-alarm-rate`", "`--strict`"):
        assert option in page
    assert "`--overwrite`" not in page  # an old spelling, refused, is not documented as one
