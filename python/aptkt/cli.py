"""The ``aptkt`` command line. Each sub-command lives in :mod:`aptkt.commands`."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from aptkt import __version__
from aptkt.errors import AptktError

# One module per sub-command (or group); each defines ``register(subparsers)`` which adds its
# parser and sets ``func`` (called with the parsed arguments, returns an exit code).
COMMAND_MODULES: tuple[str, ...] = (
    "aptkt.commands.demo",
    "aptkt.commands.skin",
    "aptkt.commands.dataset",
    "aptkt.commands.prior",
    "aptkt.commands.collect",
    "aptkt.commands.learn",
    "aptkt.commands.reproduce",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="aptkt",
        description="Active Prior Tactile Knowledge Transfer: tactile object learning with a robot skin.",
    )
    parser.add_argument("--version", action="version", version=f"aptkt {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def _version() -> str:
    return __version__


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except AptktError as exc:
        print(f"aptkt {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"aptkt {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
