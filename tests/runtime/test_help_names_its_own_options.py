"""A command's help names only options that command has: ``benchmark --help`` once sent
readers to ``--prior`` and ``--auxiliary``, which belong to ``learn``."""

from __future__ import annotations

import argparse
import re

import pytest

from aptkt.cli import build_parser
from aptkt.reference import _subcommands


def _commands(parser: argparse.ArgumentParser, path: str = "aptkt"):
    subs = _subcommands(parser)
    if not subs:
        yield path, parser
    for name, sub in subs.items():
        yield from _commands(sub, f"{path} {name}")


COMMANDS = dict(_commands(build_parser()))


def _options(parser: argparse.ArgumentParser) -> set[str]:
    return {s for a in parser._actions for s in a.option_strings}


#: A command by its last word: a help text may send the reader to another command's option
#: ("prior inspect --json shows it").
BY_NAME = {path.rsplit(" ", 1)[-1]: parser for path, parser in COMMANDS.items()}


@pytest.mark.parametrize("path", sorted(COMMANDS))
def test_every_option_a_help_text_names_is_the_commands_own(path):
    parser = COMMANDS[path]
    texts = [parser.description or ""] + [a.help or "" for a in parser._actions]
    wrong = []
    for text in texts:
        for before, option in re.findall(r"(\w*)\s*(?<![\w-])(--[a-z][a-z0-9-]*)", text):
            where = BY_NAME.get(before, parser)
            if option not in _options(where):
                wrong.append(f"{before} {option}".strip())
    assert not wrong, f"{path} --help names {wrong}, which it does not have"
