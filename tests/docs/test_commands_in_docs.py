"""Docs that cannot lie about the command line: every `aptkt ...` and
`python -m aptkt.sim.loopback ...` command the README and docs/ show, in a code block or a code
span, names commands that exist and options those commands take, and every bare `--option` the
prose mentions is one of the command line's."""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from aptkt.cli import build_parser
from aptkt.sim.loopback.__main__ import build_parser as build_loopback_parser

ROOT = Path(__file__).resolve().parents[2]
#: The research log records commands as they were run, options since removed included.
HISTORY = {ROOT / "docs" / "dev" / "research-log.md"}
DOCS = [p for p in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))] if p not in HISTORY]
#: Options the docs name that belong to other tools, with the tool.
OTHER_TOOLS = {"--quiet": "mkdocs build (docs/dev/site.md)"}

FENCE = re.compile(r"^\s*```")
SPAN = re.compile(r"`([^`]+)`")
OPTION = re.compile(r"(?<![\w-])--[a-z][\w-]*")
PROGRAMS = {"aptkt": build_parser, "python -m aptkt.sim.loopback": build_loopback_parser}


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _long_options(parser: argparse.ArgumentParser) -> set[str]:
    found = {o for o in parser._option_string_actions if o.startswith("--")}
    for child in _subcommands(parser).values():
        found |= _long_options(child)
    return found


def _program(line: str) -> str | None:
    line = line.removeprefix("$ ")
    for program in PROGRAMS:
        if line == program or line.startswith(program + " "):
            return program
    return None


def command_lines(text: str) -> list[tuple[int, str]]:
    """(line number, command) of every command of ours: fenced lines (continuations joined)
    and code spans."""
    found: list[tuple[int, str]] = []
    fenced = False
    pending, start = "", 0
    for n, line in enumerate(text.splitlines(), 1):
        if FENCE.match(line):
            fenced = not fenced
            continue
        if fenced:
            stripped = line.strip().removeprefix("$ ")
            if not pending and _program(stripped) is None:
                continue
            if not pending:
                start = n
            pending = f"{pending} {stripped}".strip()
            if pending.endswith("\\"):
                pending = pending[:-1].rstrip()
                continue
            found.append((start, pending))
            pending = ""
        else:
            found += [(n, span) for span in SPAN.findall(line) if _program(span)]
    return found


def check_command(command: str) -> list[str]:
    """What in one command the parser does not know; empty if it knows everything."""
    program = _program(command)
    assert program is not None
    parser = PROGRAMS[program]()
    try:
        tokens = shlex.split(command[len(program) :], comments=True)
    except ValueError:  # an unbalanced quote in prose: check the words as they stand
        tokens = command[len(program) :].split()
    if tokens and tokens[0].endswith(":"):  # an error message: "aptkt learn: error: ..."
        return []
    problems = []
    i = 0
    while i < len(tokens) and (children := _subcommands(parser)):
        word = tokens[i]
        if word.startswith("-") or not re.fullmatch(r"[a-z][\w-]*", word):
            break  # an option, or a placeholder such as COMMAND or <command>
        if word not in children:
            return [f"{parser.prog} has no command {word!r}"]
        parser, i = children[word], i + 1
    for token in tokens[i:]:
        option = token.split("=", 1)[0]
        if OPTION.fullmatch(option) and option not in parser._option_string_actions:
            problems.append(f"{parser.prog} has no option {option}")
    return problems


def bare_options(text: str) -> list[tuple[int, str]]:
    """Options named in code spans that are not commands (`--priors`, `--cutoff paper`)."""
    return [
        (n, option)
        for n, line in enumerate(text.splitlines(), 1)
        for span in SPAN.findall(line)
        if span.startswith("--")
        for option in OPTION.findall(span)
    ]


@pytest.mark.parametrize("md", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_command_in_the_docs_parses(md):
    text = md.read_text(encoding="utf-8")
    problems = [
        f"{md.relative_to(ROOT)}:{n}: {problem}: {command}"
        for n, command in command_lines(text)
        for problem in check_command(command)
    ]
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("md", DOCS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_option_the_docs_name_exists(md):
    known = set(OTHER_TOOLS)
    for build in PROGRAMS.values():
        known |= _long_options(build())
    unknown = [
        f"{md.relative_to(ROOT)}:{n}: {option}"
        for n, option in bare_options(md.read_text(encoding="utf-8"))
        if option not in known
    ]
    assert not unknown, "\n".join(unknown)


def test_the_docs_show_commands_at_all():
    """The collector finds what it is meant to: a page with no command would pass vacuously."""
    assert len([c for md in DOCS for c in command_lines(md.read_text(encoding="utf-8"))]) > 100


def test_other_tools_options_are_not_ours():
    ours = set().union(*(_long_options(build()) for build in PROGRAMS.values()))
    assert not ours & set(OTHER_TOOLS)


@pytest.mark.parametrize(
    "command,problem",
    [
        (
            "aptkt learn --table t.csv --feature-space prior",
            "aptkt learn has no option --feature-space",
        ),
        ("aptkt prior frobnicate x.npz", "aptkt prior has no command 'frobnicate'"),
        ("aptkt benchmark t.csv --priors=3,5 --strict", None),
        ("aptkt learn: error: features.csv: missing column(s) trial", None),
        ("python -m aptkt.sim.loopback --series e-series --nope", "has no option --nope"),
        ("aptkt COMMAND --help", None),
    ],
)
def test_the_checker_catches_what_it_should(command, problem):
    found = check_command(command)
    if problem is None:
        assert found == []
    else:
        assert any(problem in p for p in found), found


def test_fenced_continuations_are_joined():
    text = "```bash\naptkt learn --table t.csv \\\n    --nope 1   # comment\n```\n"
    ((n, command),) = command_lines(text)
    assert n == 2 and check_command(command) == ["aptkt learn has no option --nope"]
