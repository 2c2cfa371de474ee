"""``aptkt benchmark``: APTKT against its baseline on any sensor's feature table (real data)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from aptkt.commands._checks import add_jobs_option, add_scheduler_option
from aptkt.commands._inputs import add_trials_option
from aptkt.commands._method import add_method_arguments
from aptkt.experiments.schedule import LARGEST_BATCH
from aptkt.files import present

DEFAULTS = {"groups": 60, "new": 5, "priors": "3", "budget": 20}
#: Objects in a synthetic stream (--from): a library a lab would hold after a few years.
DEFAULT_STREAM = 1000
#: What a benchmark writes, its plots too: any of them in --output (a link to anywhere too)
#: would be replaced.
BENCHMARK_FILES = (
    "report.md",
    "summary.json",
    "results.csv",
    *(f"{plot}.{ext}" for plot in ("benchmark", "library", "lifelong") for ext in ("png", "svg")),
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "benchmark",
        help="APTKT vs the baseline on a feature table of real data: paired gains, plots, report",
        description="Draws groups of new objects and, for each, prior objects at random, the "
        "most similar and the least similar (for every library size of --priors, larger "
        "libraries holding the smaller ones); learns the new objects with the baseline, APTKT, "
        "APTKT with auxiliary features and the control (the prior's feature space and kernel, "
        "no transfer), and compares them with two 1-nearest-neighbour rules (in the prior's "
        "metric, and in the priors' shrunk within-object covariance). The first half of each "
        "object's trials builds the priors and is the pool; the second half is held out. "
        "Writes report.md, benchmark.png/.svg, library.png/.svg (several sizes), results.csv "
        "and summary.json. See docs/real-data.md.",
    )
    p.add_argument(
        "table",
        metavar="TABLE",
        nargs="?",
        help="feature table (.csv, .h5; docs/feature-tables.md); with --lifelong --from, none",
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
        "--priors",
        default=DEFAULTS["priors"],
        metavar="N[,N...]",
        help="prior objects per group: one library size, or several in increasing order to "
        "sweep them on the same groups, e.g. 3,5,10,15 (default %(default)s)",
    )
    p.add_argument(
        "--choices",
        metavar="KIND,...",
        help="how the priors are chosen: random, nearest, farthest (default: all three)",
    )
    p.add_argument("--actions", metavar="A,B,...", help="only these actions (default: all)")
    add_trials_option(p, "rows (chosen before each object's trials are halved)")
    p.add_argument(
        "--lifelong",
        action="store_true",
        help="instead: a library that grows — in --orders random orders of the objects, the "
        "first --new objects start the library, then each next --new objects are learned "
        "(APTKT with the library, the baseline with nothing) and merged into it; writes "
        "report.md, lifelong.png/.svg, results.csv, summary.json",
    )
    p.add_argument(
        "--recognition",
        action="store_true",
        help="instead: recognition — in --groups random draws, a library of --priors objects "
        "(the first half of their trials) recognises the second half of their trials and of "
        "--new objects it does not hold; accuracy against a nearest-class-mean rule, novelty "
        "AUROC, false alarms (docs/recognition.md)",
    )
    p.add_argument(
        "--from",
        dest="population",
        metavar="TABLE",
        help="with --lifelong: instead of a table's own objects, a stream of --stream synthetic "
        "objects drawn from the population fitted on TABLE (its objects' within-object noise "
        "and between-object spread; docs/method.md), in batches growing with the library from "
        f"--new to {LARGEST_BATCH} objects",
    )
    p.add_argument(
        "--stream",
        type=int,
        default=DEFAULT_STREAM,
        metavar="N",
        help="with --from: objects in each order's stream (default %(default)s)",
    )
    p.add_argument(
        "--orders",
        type=int,
        default=20,
        metavar="N",
        help="with --lifelong: random orders of the objects (default %(default)s)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="seed of the groups and runs (default %(default)s)",
    )
    add_jobs_option(p, "learn")
    add_scheduler_option(p)
    p.add_argument("--force", action="store_true", help="replace the results in --output")
    p.add_argument(
        "--strict",
        action="store_true",
        help="exit with status 1 when a check that must hold on any data fails (for a lab's "
        "CI); the results are written either way",
    )
    p.add_argument(
        "--strict-reference",
        action="store_true",
        help="as --strict, and also when a reference figure (the paper's, on the BioTac set) is "
        "not reached on this data",
    )
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress (a bar on a terminal, otherwise a line every tenth of the groups or "
        "30 s on standard error)",
    )
    add_method_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # The arguments and the table are checked before the learner (and scikit-learn) loads.
    from aptkt.commands._checks import (
        MAX_BUDGET,
        MAX_RUNS,
        at_least,
        at_most,
        jobs,
        known_names,
        output_dir,
        scheduler_available,
    )
    from aptkt.commands._inputs import check_trials, parse_trials, refuse_data_set
    from aptkt.commands._method import learner_config
    from aptkt.commands._session import split_names
    from aptkt.errors import ConfigError
    from aptkt.experiments.benchmark_settings import (
        PRIOR_CHOICES,
        BenchmarkSettings,
        check_enough_objects,
        check_lifelong_objects,
        check_recognition_objects,
    )
    from aptkt.experiments.table_limits import MAX_LIBRARY_OBJECTS, read_table_within_limits

    jobs(args.jobs)
    trials = parse_trials(args.trials)
    at_least(args.seed, 0, "--seed")
    at_least(args.groups, 1, "--groups")
    at_most(args.groups, MAX_RUNS, "--groups")
    at_least(args.new, 2, "--new")
    libraries = _library_sizes(args.priors)
    at_least(args.budget, 0, "--budget")
    if args.lifelong:
        sweep_only = [
            option
            for option, given in (
                ("--groups", args.groups != DEFAULTS["groups"]),
                ("--priors", args.priors != DEFAULTS["priors"]),
                ("--choices", args.choices is not None),
            )
            if given
        ]
        if sweep_only:
            raise ConfigError(
                f"{', '.join(sweep_only)}: not with --lifelong (its library grows from --new "
                "objects in --orders orders)"
            )
    if args.recognition and (args.lifelong or len(libraries) > 1):
        raise ConfigError("--recognition: one library size (--priors N), and not with --lifelong")
    if args.population is not None:
        if not args.lifelong:
            raise ConfigError("--from: only with --lifelong (a synthetic stream of objects)")
        if args.table is not None:
            raise ConfigError(
                f"--from {args.population} and TABLE {args.table}: give one (--from draws the "
                "objects from a population fitted on its table; TABLE uses its own objects)"
            )
        at_least(args.stream, 2 * args.new, "--stream")
        at_most(args.stream, MAX_LIBRARY_OBJECTS, "--stream", "the objects a library holds")
        args.table = args.population
    elif args.stream != DEFAULT_STREAM:
        raise ConfigError("--stream: only with --from (the synthetic stream's length)")
    if args.table is None:
        raise ConfigError("TABLE: give a feature table (or, with --lifelong, --from TABLE)")
    at_least(args.orders, 1, "--orders")
    at_most(args.orders, MAX_RUNS, "--orders")
    at_most(args.budget, MAX_BUDGET, "--budget")
    refuse_data_set(args.table, "aptkt benchmark", "--from" if args.population else "TABLE")
    output_dir(args.output)
    scheduler_available(args.scheduler)
    if any(present(args.output / f) for f in BENCHMARK_FILES) and not args.force:
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
            libraries=libraries,
            budget=args.budget,
            seed=args.seed,
            choices=choices,
            actions=tuple(split_names(args.actions, "--actions") or ()) or None,
            config=config,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    table = read_table_within_limits(args.table, settings)
    if trials is not None:
        # Before the benchmark halves each object's trials into priors/pool and held-out rows.
        check_trials(trials, table.trials.tolist(), args.table)
        table = table.take(trials.mask(table.trials))
    known_names(settings.actions, table.action_names, "--actions")
    # Enough objects for what was asked, before the learner loads.
    if args.recognition:
        check_recognition_objects(table.object_names, libraries[0], args.new)
    elif args.lifelong:
        if args.population is None:  # (--from: the stream's objects, checked above)
            check_lifelong_objects(table.object_names, args.new)
    else:
        check_enough_objects(table.object_names, settings)
    if args.recognition:
        from aptkt.experiments.recognition_benchmark import run_recognition_benchmark

        run_recognition_benchmark(
            table,
            groups=args.groups,
            library=libraries[0],
            unseen=args.new,
            seed=args.seed,
            actions=list(settings.actions) if settings.actions else None,
            output=args.output,
            jobs=args.jobs,
            command=_command(args),
            say=lambda line: print(line, flush=True),
        )
        return 0
    # How either benchmark runs and reports, whichever it is.
    run: dict[str, Any] = {
        "output": args.output,
        "jobs": args.jobs,
        "scheduler": args.scheduler,
        "command": _command(args),
        "progress": not args.no_progress,
        "say": lambda line: print(line, flush=True),
    }
    if args.lifelong:
        from aptkt.experiments.lifelong import LifelongSettings, run_lifelong

        summary = run_lifelong(
            table,
            LifelongSettings(
                orders=args.orders,
                batch=args.new,
                budget=args.budget,
                seed=args.seed,
                actions=settings.actions,
                config=config,
                stream=args.stream if args.population is not None else None,
            ),
            **run,
        )
        return _strict_exit(args, summary)
    from aptkt.experiments.benchmark import run_benchmark

    return _strict_exit(args, run_benchmark(table, settings, **run))


def _strict_exit(args: argparse.Namespace, summary: dict) -> int:
    """0, or 1 with --strict when a check that must hold on any data failed, with
    --strict-reference also when a reference figure was not reached; the results are written
    either way."""
    from aptkt.experiments.benchmark_report import CHECK_KINDS, INVARIANT, failed_checks

    kinds: tuple[str, ...]
    if args.strict_reference:
        kinds, option, what = CHECK_KINDS, "--strict-reference", "check(s) failed or not reached"
    elif args.strict:
        kinds, option, what = (INVARIANT,), "--strict", "check(s) failed"
    else:
        return 0
    failed = failed_checks(summary["checks"], kinds)
    if failed:
        print(
            f"aptkt benchmark: {len(failed)} {what} ({option}): see {args.output / 'report.md'}",
            file=sys.stderr,
        )
        return 1
    return 0
    kinds = CHECK_KINDS if args.strict == "all" else (INVARIANT,)
    failed = failed_checks(summary["checks"], kinds)
    if failed:
        what = (
            "check(s) failed or reference figure(s) not reached"
            if args.strict == "all"
            else ("check(s) failed")
        )
        print(
            f"aptkt benchmark: {len(failed)} {what} (--strict {args.strict}): see "
            f"{args.output / 'report.md'}",
            file=sys.stderr,
        )
        return 1
    return 0


def _library_sizes(text: str) -> tuple[int, ...]:
    """``--priors``: one size or several, comma-separated, distinct, increasing, each >= 2."""
    from aptkt.commands._checks import at_least
    from aptkt.errors import ConfigError

    parts = [p.strip() for p in str(text).split(",")]
    try:
        sizes = tuple(int(p) for p in parts)
    except ValueError:
        raise ConfigError(
            f"--priors: {text!r} is not a number or a comma-separated list of numbers"
        ) from None
    for k in sizes:
        at_least(k, 2, "--priors")
    if list(sizes) != sorted(set(sizes)):
        raise ConfigError(f"--priors: library sizes must be distinct and increasing, got {text}")
    return sizes


def _command(args: argparse.Namespace) -> str:
    source = f"--from {args.population}" if args.population else str(args.table)
    parts = ["aptkt benchmark", source, f"-o {args.output}"]
    for option, default in DEFAULTS.items():
        if getattr(args, option) != default:
            parts.append(f"--{option} {getattr(args, option)}")
    for option in ("choices", "actions", "trials", "scheduler"):
        if getattr(args, option):
            parts.append(f"--{option} {getattr(args, option)}")
    if args.recognition:
        parts.append("--recognition")
    if args.lifelong:
        parts.append("--lifelong")
        if args.orders != 20:
            parts.append(f"--orders {args.orders}")
        if args.population:
            parts.append(f"--stream {args.stream}")
    if args.strict_reference:
        parts.append("--strict-reference")
    elif args.strict:
        parts.append("--strict")
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
