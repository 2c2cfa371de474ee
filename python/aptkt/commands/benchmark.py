"""``aptkt benchmark``: APTKT against its baseline on any sensor's feature table (real data)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from aptkt.commands._checks import add_jobs_option
from aptkt.commands._method import add_method_arguments

DEFAULTS = {"groups": 60, "new": 5, "priors": 3, "budget": 20}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "benchmark",
        help="APTKT vs the baseline on a feature table of real data: paired gains, plots, report",
        description="Draws groups of new objects and, for each, prior objects at random, the "
        "most similar and the least similar; learns the new objects with the baseline, APTKT, "
        "APTKT with auxiliary features and the control (the prior's feature space and kernel, "
        "no transfer), and compares them with a 1-nearest-neighbour rule in the prior's "
        "metric. The first half of each object's trials builds the priors and is the pool; the "
        "second half is held out. Writes report.md, benchmark.png/.svg, results.csv and "
        "summary.json. See docs/real-data.md.",
    )
    p.add_argument(
        "table", metavar="TABLE", help="feature table (.csv, .h5; docs/feature-tables.md)"
    )
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        default=Path("aptkt-benchmark"),
        metavar="DIR",
        help="output directory (default %(default)s)",
    )
    for option, what in (
        ("groups", "groups of new objects"),
        ("new", "new objects per group"),
        ("priors", "prior objects per group"),
        ("budget", "actively chosen observations after the first round"),
    ):
        p.add_argument(
            f"--{option}",
            type=int,
            default=DEFAULTS[option],
            metavar="N",
            help=f"{what} (default %(default)s)",
        )
    p.add_argument(
        "--choices",
        metavar="KIND,...",
        help="how the priors are chosen: random, nearest, farthest (default: all three)",
    )
    p.add_argument("--actions", metavar="A,B,...", help="only these actions (default: all)")
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="seed of the groups and runs (default %(default)s)",
    )
    add_jobs_option(p, "processes (default: all cores)", all_cores=True)
    p.add_argument("--force", action="store_true", help="replace the results in --output")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_method_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from aptkt.commands._checks import (
        MAX_BUDGET,
        MAX_RUNS,
        at_least,
        at_most,
        input_file,
        jobs,
        output_dir,
    )
    from aptkt.commands._method import learner_config
    from aptkt.commands._session import split_names
    from aptkt.errors import ConfigError
    from aptkt.experiments.benchmark import PRIOR_CHOICES, BenchmarkSettings, run_benchmark
    from aptkt.experiments.table_limits import read_table_within_limits

    jobs(args.jobs)
    at_least(args.seed, 0, "--seed")
    at_least(args.groups, 1, "--groups")
    at_most(args.groups, MAX_RUNS, "--groups")
    at_least(args.new, 2, "--new")
    at_least(args.priors, 2, "--priors")
    at_least(args.budget, 0, "--budget")
    at_most(args.budget, MAX_BUDGET, "--budget")
    input_file(args.table, "TABLE")
    output_dir(args.output)
    if (args.output / "report.md").exists() and not args.force:
        raise ConfigError(
            f"--output {args.output}: holds a benchmark already (give --force to replace it)"
        )
    choices = tuple(split_names(args.choices, "--choices") or PRIOR_CHOICES)
    unknown = [c for c in choices if c not in PRIOR_CHOICES]
    if unknown:
        raise ConfigError(
            f"--choices: {', '.join(unknown)}; choose from {', '.join(PRIOR_CHOICES)}"
        )
    try:
        config = learner_config(args)
        settings = BenchmarkSettings(
            groups=args.groups,
            new_objects=args.new,
            prior_objects=args.priors,
            budget=args.budget,
            seed=args.seed,
            choices=choices,
            actions=tuple(split_names(args.actions, "--actions") or ()) or None,
            config=config,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    table = read_table_within_limits(args.table, settings)
    run_benchmark(
        table,
        settings,
        output=args.output,
        jobs=args.jobs,
        command=_command(args),
        progress=not args.no_progress and sys.stderr.isatty(),
        say=lambda line: print(line, flush=True),
    )
    return 0


def _command(args: argparse.Namespace) -> str:
    parts = ["aptkt benchmark", str(args.table), f"-o {args.output}"]
    for option, default in DEFAULTS.items():
        if getattr(args, option) != default:
            parts.append(f"--{option} {getattr(args, option)}")
    for option in ("choices", "actions"):
        if getattr(args, option):
            parts.append(f"--{option} {getattr(args, option)}")
    if args.seed:
        parts.append(f"--seed {args.seed}")
    if args.reading != "aptkt":
        parts.append(f"--reading {args.reading}")
    for option in (
        "cutoff",
        "evidence_margin",
        "kernel",
        "prior_feature_scale",
    ):
        if getattr(args, option) is not None:
            parts.append(f"--{option.replace('_', '-')} {getattr(args, option)}")
    return " ".join(parts)
