"""``aptkt demo``: the README's main job — the whole method on the simulated world."""

from __future__ import annotations

import argparse
from pathlib import Path

from aptkt.commands._checks import add_jobs_option, add_renamed_option
from aptkt.learning.config import LearnerConfig


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="end-to-end demo on the simulated world: prior knowledge, APTKT vs baseline, plots",
        description="Simulates the prior and new objects, builds prior knowledge, learns the new "
        "objects with APTKT and with the baseline, and writes a table, learning curves (PNG, SVG), "
        "every result and the settings to the output directory. Re-running reuses the simulated data.",
    )
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        default=Path("aptkt-demo"),
        metavar="DIR",
        help="output directory (default %(default)s); a re-run of the same size reuses its "
        "simulated data",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="seed of the simulated world and the learners (default %(default)s)",
    )
    add_jobs_option(p, "learn")
    add_renamed_option(p, "--trials")
    p.add_argument(
        "--runs",
        type=int,
        default=3,
        metavar="N",
        help="learning runs per method (default %(default)s)",
    )
    p.add_argument(
        "--budget",
        type=int,
        default=LearnerConfig.budget,
        metavar="N",
        help="actively chosen observations (default %(default)s)",
    )
    p.add_argument(
        "--quick", action="store_true", help="a reduced size that runs in well under a minute"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from aptkt.commands._checks import MAX_BUDGET, MAX_RUNS, at_least, at_most, jobs, output_dir
    from aptkt.experiments.demo import DemoSettings, run_demo

    jobs(args.jobs)
    at_least(args.runs, 1, "--runs")
    at_most(args.runs, MAX_RUNS, "--runs")
    at_least(args.budget, 0, "--budget")
    at_most(args.budget, MAX_BUDGET, "--budget")
    at_least(args.seed, 0, "--seed")
    output_dir(args.output)
    common = dict(output=args.output, seed=args.seed, jobs=args.jobs)
    settings = (
        DemoSettings.quick(**common)
        if args.quick
        else DemoSettings(**common, trials=args.runs, budget=args.budget)
    )
    run_demo(settings, progress=not args.no_progress)
    return 0
