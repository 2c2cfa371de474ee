"""``aptkt reproduce``: the paper's experiments (Fig. 6–11) with plots and a report."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from aptkt.commands._checks import add_jobs_option, add_scheduler_option
from aptkt.commands._method import add_method_arguments, learner_config
from aptkt.commands._session import add_noise_option, noise_level

NAMES = ("fig6", "fig7", "fig8", "fig9", "fig10", "fig11", "all")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="reproduce the paper's experiments (Fig. 6-11) on the simulated world: plots, results, report",
        description="Runs the paper's experiments (§5.3-5.6) and writes, in the output directory, plots (PNG, "
        "SVG), every step of every run (CSV), report.md (our numbers beside the paper's) and config.json "
        "(everything needed to repeat the run). Without --data it simulates the data set it needs and keeps "
        "it in the output directory. Finished runs are stored as they complete: rerun the same command "
        "after an interruption and it resumes. See docs/reproduce.md.",
    )
    p.add_argument("name", choices=NAMES, help="the figure to reproduce, or all of them")
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        default=Path("aptkt-reproduce"),
        metavar="DIR",
        help="output directory (default %(default)s)",
    )
    p.add_argument(
        "--data",
        type=Path,
        metavar="DATASET",
        help="data set (HDF5) to use instead of simulating one; features are extracted into it if missing",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="a reduced size (4 priors, 3 new objects, 3 actions) for tests and CI",
    )
    add_jobs_option(p, "run locally")
    add_scheduler_option(p)
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="root seed of the data, the groups and the trials (default %(default)s)",
    )
    p.add_argument(
        "--real-data",
        type=Path,
        metavar="DIR",
        help="an aptkt benchmark output directory: the report sets its real-data gains beside "
        "this run's",
    )
    add_noise_option(p)
    add_method_arguments(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from aptkt.commands._checks import (
        at_least,
        input_file,
        intact_data_set,
        jobs,
        output_dir,
        scheduler_available,
    )
    from aptkt.errors import ConfigError
    from aptkt.experiments.reproduce import FIGURE_NAMES, ReproduceSettings, reproduce

    jobs(args.jobs)
    at_least(args.seed, 0, "--seed")
    output_dir(args.output)
    if args.data is not None:
        input_file(args.data, "--data")
        intact_data_set(args.data, "--data")
    if args.data is not None and args.noise is not None:
        raise ConfigError("--noise: only without --data (a given data set was simulated already)")
    noise = noise_level(args.noise)
    scheduler_available(args.scheduler)
    figures = FIGURE_NAMES if args.name == "all" else (args.name,)
    if args.real_data is not None:
        from aptkt.experiments.beside_real import load_benchmark

        load_benchmark(args.real_data)  # checked before any work
    try:
        base = learner_config(args)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    settings = ReproduceSettings(
        figures=figures,
        output=args.output,
        data=args.data,
        quick=args.quick,
        jobs=args.jobs,
        scheduler=args.scheduler,
        seed=args.seed,
        progress=not args.no_progress,
        base=base,
        real_data=args.real_data,
        noise=noise,
        command=_command(args),
    )
    try:
        reproduce(settings)
    except KeyboardInterrupt:
        print(
            f"interrupted: finished runs are kept in {args.output / 'runs'}; run the same command again to resume",
            file=sys.stderr,
        )
        raise
    return 0


def _command(args: argparse.Namespace) -> str:
    """The command line as given (for the report)."""
    parts = ["aptkt reproduce", args.name, f"--output {args.output}"]
    if args.data is not None:
        parts.append(f"--data {args.data}")
    if args.quick:
        parts.append("--quick")
    if args.noise is not None:
        parts.append(f"--noise {args.noise}")
    parts.append(f"--jobs {args.jobs}")
    if args.scheduler:
        parts.append(f"--scheduler {args.scheduler}")
    parts.append(f"--seed {args.seed}")
    if args.real_data is not None:
        parts.append(f"--real-data {args.real_data}")
    if args.reading != "aptkt":
        parts.append(f"--reading {args.reading}")
    for option in ("cutoff", "evidence_margin", "kernel"):
        value = getattr(args, option)
        if value is not None:
            parts.append(f"--{option.replace('_', '-')} {value}")
    if args.prior_feature_scale is not None:
        parts.append(f"--prior-feature-scale {args.prior_feature_scale}")
    return " ".join(parts)
