"""``aptkt demo``: the README's main job."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the end-to-end demo on the simulated world")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    print("aptkt demo: not implemented yet")
    return 1
