"""The command-line reference (docs/cli.md), generated from the parsers themselves so that it
cannot drift from them: ``python -m aptkt.reference > docs/cli.md``. A test compares
the page with what this prints.

Markdown tables of each command's options rather than argparse's help text: the help text's
layout depends on the terminal's width and on the Python version, the tables on neither."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator

from aptkt.cli import build_parser

__all__ = ["markdown_reference"]

HEADER = """# Command-line reference

Generated from the command line itself (`python -m aptkt.reference > docs/cli.md`;
a test fails when this page and the command line differ). `aptkt COMMAND --help` prints the
same. Every mistake ends in one `aptkt COMMAND: error: ...` line; the exit codes are in
[Reliability](reliability.md).
"""


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _summaries(parser: argparse.ArgumentParser) -> dict[str, str]:
    """Each sub-command's one-line help, as the parent lists it."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return {a.dest: a.help or "" for a in action._choices_actions}
    return {}


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


def _argument(action: argparse.Action) -> str:
    names = (
        ", ".join(f"`{o}`" for o in action.option_strings) or f"`{action.metavar or action.dest}`"
    )
    if action.nargs == 0:
        return names
    if action.choices is not None and action.metavar is None:
        value = "{" + ",".join(str(c) for c in action.choices) + "}"
    else:
        metavar = action.metavar or action.dest.upper()
        value = " ".join(metavar) if isinstance(metavar, tuple) else str(metavar)
    return f"{names} `{value}`" if action.option_strings else names


def _help(action: argparse.Action) -> str:
    text = action.help or ""
    params = {"default": action.default, "prog": "aptkt"}
    if action.choices is not None:
        params["choices"] = ", ".join(map(str, action.choices))
    try:
        return _cell(text % params)
    except (KeyError, ValueError, TypeError):
        return _cell(text)


def _sections(parser: argparse.ArgumentParser, path: str, summary: str) -> Iterator[str]:
    children = _subcommands(parser)
    level = "#" * min(path.count(" ") + 1, 4)
    if path != "aptkt":
        yield f"\n{level} `{path}`\n"
        if summary:
            yield "\n" + _cell(summary) + "\n"
    if parser.description and path != "aptkt":
        yield "\n" + " ".join(parser.description.split()) + "\n"
    shown = [
        a
        for a in parser._actions
        if a.help != argparse.SUPPRESS
        and not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))
    ]
    if shown and path != "aptkt":
        yield "\n| argument | meaning |\n|---|---|\n"
        for action in shown:
            yield f"| {_argument(action)} | {_help(action)} |\n"
    summaries = _summaries(parser)
    for name, child in children.items():
        yield from _sections(child, f"{path} {name}", summaries.get(name, ""))


def markdown_reference(parser: argparse.ArgumentParser) -> str:
    """The reference page of ``parser`` and all its sub-commands, as Markdown."""
    lines = [HEADER]
    summaries = _summaries(parser)
    lines.append("\n| command | what it does |\n|---|---|\n")
    for name in _subcommands(parser):
        lines.append(f"| [`aptkt {name}`](#aptkt-{name}) | {_cell(summaries.get(name, ''))} |\n")
    lines += list(_sections(parser, "aptkt", ""))
    return "".join(lines)


def main() -> int:
    sys.stdout.write(markdown_reference(build_parser()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
