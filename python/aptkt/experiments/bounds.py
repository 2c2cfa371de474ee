"""Bounds of an experiment's counts, shared by the command line (``aptkt.commands._checks``)
and the Python entry points (``compare_on_data``): one number for each, checked before any
work starts."""

from __future__ import annotations

__all__ = ["MAX_BUDGET", "MAX_RUNS"]

#: Observations a learning run may choose (--budget, --patience): every one is a trial on the
#: robot, and the models are refitted on all of them after each.
MAX_BUDGET = 10_000
#: Learning runs per method (demo --runs, learn --runs).
MAX_RUNS = 1_000
