"""``aptkt learn TABLE``: learn new objects from a feature table of any sensor, offline.

The options of this mode; :mod:`aptkt.commands.learn` dispatches to :func:`run` when a table
is given (TABLE, or ``--table TABLE`` as it was written before).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from aptkt.commands._checks import (
    MAX_BUDGET,
    MAX_RUNS,
    at_most,
    check_target_accuracy,
    output_dir,
)
from aptkt.commands._inputs import add_trials_option, check_trials, parse_trials
from aptkt.commands._method import learner_config
from aptkt.commands._session import split_names
from aptkt.errors import ConfigError
from aptkt.learning.pipeline import EXTRACTIONS, SKIN_EXTRACTION

DEFAULT_RUNS = 3


def add_extraction_argument(p: argparse._ActionsContainer) -> None:
    """``--extraction``: whose features a feature table holds (learn --table, prior build)."""
    p.add_argument(
        "--extraction",
        choices=EXTRACTIONS,
        default="auto",
        help=f"whose features the table holds: {SKIN_EXTRACTION}, this skin's as aptkt extracts "
        "them (the texture's activities log-scaled, the thermal curve reduced by PCA, as when "
        "learning from a data set); other, any sensor's (each column z-scored as it is); auto, "
        f"as the table's extraction column says (aptkt dataset export-features writes "
        f"{SKIN_EXTRACTION}), other without one (default %(default)s)",
    )


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group(
        "from a feature table (no robot)",
        "aptkt learn TABLE learns from recorded feature observations (CSV or HDF5: columns "
        "object, action, trial, <modality>.<k>; see docs/feature-tables.md) and compares APTKT, "
        "APTKT with auxiliary features and the baseline, as the demo does.",
    )
    g.add_argument(
        "--table",
        metavar="TABLE",
        help="the same as giving TABLE (the earlier spelling)",
    )
    add_trials_option(g, "rows")
    g.add_argument(
        "--prior-objects",
        metavar="A,B,...",
        help="the objects whose rows build the prior knowledge (with TABLE)",
    )
    g.add_argument(
        "--test-trials",
        metavar="TRIALS",
        help="hold out the new objects' rows of these trials, written as for --trials (default: "
        "the later half of each object's trials per action)",
    )
    g.add_argument(
        "--runs",
        type=int,
        metavar="N",
        help=f"learning runs per method (with TABLE; default {DEFAULT_RUNS})",
    )
    add_extraction_argument(g)


def table_only(args: argparse.Namespace) -> list[str]:
    """The options of this mode that were given (an error without a table)."""
    given = {
        "--trials": args.trials,
        "--prior-objects": args.prior_objects,
        "--test-trials": args.test_trials,
        "--runs": args.runs,
        "--extraction": None if args.extraction == "auto" else args.extraction,
    }
    return [option for option, value in given.items() if value is not None]


def run(args: argparse.Namespace) -> int:
    from aptkt.experiments.table_learning import (
        TableSettings,
        learn_from_table,
        read_settings_table,
        refuse_overwrite,
    )

    trials = parse_trials(args.trials)
    test_trials = parse_trials(args.test_trials, "--test-trials")

    live_only = [
        option
        for option, value in (
            ("--prior", args.prior),
            ("--transfer", args.transfer),
            ("--auxiliary", args.auxiliary),
            ("--robot", args.robot),
            ("--test", args.test),
            ("--record", args.record),
        )
        if value
    ]
    if live_only:
        raise ConfigError(
            f"{', '.join(live_only)}: not with a table, which builds its prior knowledge from "
            "--prior-objects and compares APTKT, APTKT+aux and the baseline on held-out rows"
        )
    priors = split_names(args.prior_objects, "--prior-objects")
    if not priors:
        raise ConfigError(
            "learning from a table needs --prior-objects A,B,... (the objects of prior knowledge)"
        )
    runs = DEFAULT_RUNS if args.runs is None else args.runs
    if runs < 1:
        raise ConfigError("--runs must be >= 1")
    at_most(runs, MAX_RUNS, "--runs")
    at_most(args.budget, MAX_BUDGET, "--budget")
    at_most(args.patience, MAX_BUDGET, "--patience")
    check_target_accuracy(args.target_accuracy)
    try:  # the learner's own checks of the options, as a one-line error
        config = learner_config(
            args,
            **({} if args.eps_neg is None else {"eps_neg": args.eps_neg}),
            eps_explor=args.eps_explor,
            budget=args.budget,
            patience=args.patience,
            target_accuracy=args.target_accuracy,
            seed=args.seed,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    output_dir(args.output)
    refuse_overwrite(args.output, args.force, how="--force", where=f"--output {args.output}:")
    settings = TableSettings(
        table=Path(args.table),
        prior_objects=tuple(priors),
        new_objects=tuple(split_names(args.objects, "--objects") or ()),  # a required option
        actions=tuple(split_names(args.actions, "--actions") or ()) or None,
        test_trials=None,
        output=args.output,
        runs=runs,
        config=config,
        extraction=args.extraction,
        trials=None if trials is None else str(trials),
    )
    table = None
    if trials is not None or test_trials is not None:
        table = read_settings_table(settings)
        have = table.trials.tolist()
        check_trials(trials, have, settings.table)
        if trials is not None:
            table = table.take(trials.mask(table.trials))
        if test_trials is not None:
            settings.test_trials = tuple(t for t in sorted(set(have)) if t in test_trials)
    learn_from_table(settings, say=lambda line: print(line, flush=True), table=table)
    return 0
