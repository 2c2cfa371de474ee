"""``aptkt learn --table TABLE``: learn new objects from a feature table of any sensor, offline.

The options of this mode; :mod:`aptkt.commands.learn` dispatches to :func:`run` when ``--table``
is given.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from aptkt.commands._checks import MAX_BUDGET, MAX_RUNS, at_most, output_dir
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
        "--table TABLE learns from recorded feature observations (CSV or HDF5: columns object, "
        "action, trial, <modality>.<k>; see docs/feature-tables.md) and compares APTKT, APTKT "
        "with auxiliary features and the baseline, as the demo does.",
    )
    g.add_argument("--table", metavar="TABLE", help="feature table (.csv, .h5)")
    g.add_argument(
        "--prior-objects",
        metavar="A,B,...",
        help="the objects whose rows build the prior knowledge (with --table)",
    )
    g.add_argument(
        "--test-trials",
        metavar="FIRST:STOP",
        help="hold out the new objects' rows with these trial numbers (default: the later half "
        "of each object's trials per action)",
    )
    g.add_argument(
        "--runs",
        type=int,
        metavar="N",
        help=f"learning runs per method (with --table; default {DEFAULT_RUNS})",
    )
    add_extraction_argument(g)


def table_only(args: argparse.Namespace) -> list[str]:
    """The options of this mode that were given (an error without --table)."""
    given = {
        "--prior-objects": args.prior_objects,
        "--test-trials": args.test_trials,
        "--runs": args.runs,
        "--extraction": None if args.extraction == "auto" else args.extraction,
    }
    return [option for option, value in given.items() if value is not None]


def _trials(text: str) -> tuple[int, ...]:
    try:
        first, stop = (int(v) for v in text.split(":"))
    except ValueError:
        raise ConfigError(
            f"--test-trials must look like FIRST:STOP (e.g. 10:20), got {text!r}"
        ) from None
    if not 0 <= first < stop:
        raise ConfigError(f"--test-trials: need 0 <= FIRST < STOP, got {text!r}")
    return tuple(range(first, stop))


def run(args: argparse.Namespace) -> int:
    from aptkt.experiments.table_learning import TableSettings, learn_from_table, refuse_overwrite

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
            f"{', '.join(live_only)}: not with --table, which builds its prior knowledge from "
            "--prior-objects and compares APTKT, APTKT+aux and the baseline on held-out rows"
        )
    priors = split_names(args.prior_objects, "--prior-objects")
    if not priors:
        raise ConfigError("--table needs --prior-objects A,B,... (the objects of prior knowledge)")
    runs = DEFAULT_RUNS if args.runs is None else args.runs
    if runs < 1:
        raise ConfigError("--runs must be >= 1")
    at_most(runs, MAX_RUNS, "--runs")
    at_most(args.budget, MAX_BUDGET, "--budget")
    at_most(args.patience, MAX_BUDGET, "--patience")
    try:  # the learner's own checks of the options, as a one-line error
        config = learner_config(
            args,
            **({} if args.eps_neg is None else {"eps_neg": args.eps_neg}),
            eps_explor=args.eps_explor,
            budget=args.budget,
            patience=args.patience,
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
        test_trials=_trials(args.test_trials) if args.test_trials else None,
        output=args.output,
        runs=runs,
        config=config,
        extraction=args.extraction,
    )
    learn_from_table(settings, say=lambda line: print(line, flush=True))
    return 0
