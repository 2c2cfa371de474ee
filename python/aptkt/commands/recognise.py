"""``aptkt recognise``: which known object each touch is, how sure, or none of them."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from aptkt.commands._checks import output_dir
from aptkt.commands._inputs import (
    DATASET,
    Trials,
    add_trials_option,
    check_trials,
    dataset_trials,
    input_kind,
    parse_trials,
)
from aptkt.errors import ConfigError
from aptkt.files import present

#: Everything recognise writes: any of it in --output would be replaced.
RESULT_FILES = ("predictions.csv", "summary.json", "confusion.png", "confusion.svg")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "recognise",
        help="recognise touches with a library: the known object, how sure, or new",
        description="For each touch (one row of a feature table, or a data set's recordings; "
        "rows of several actions with the same object and trial are one touch), the most "
        "probable object of the library, its probability and the runner-up, a novelty score "
        "(higher: less like any known object) and whether it is known, at a threshold chosen "
        "on the library itself for --false-alarm-rate. Writes DIR/predictions.csv, "
        "DIR/summary.json and DIR/confusion.png/.svg. See docs/recognition.md.",
    )
    p.add_argument(
        "--prior",
        type=Path,
        required=True,
        metavar="PRIOR",
        help="the library (.npz of aptkt prior build or merge)",
    )
    p.add_argument(
        "input",
        type=Path,
        nargs="?",
        metavar="DATASET|TABLE",
        help="the touches: a feature table (.csv, .h5) or a data set (HDF5) of this skin, told "
        "apart by what the file holds",
    )
    p.add_argument(
        "--table",
        type=Path,
        metavar="TABLE",
        help="the same as giving TABLE as DATASET|TABLE (the earlier spelling)",
    )
    add_trials_option(p, "touches")
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        default=Path("aptkt-recognise"),
        metavar="DIR",
        help="output directory (default %(default)s)",
    )
    p.add_argument(
        "--false-alarm-rate",
        type=float,
        default=0.05,
        metavar="RATE",
        help="share of touches of known objects the threshold may flag as new, chosen on the "
        "library (default %(default)s)",
    )
    p.add_argument("--force", action="store_true", help="replace the results in --output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from aptkt.commands.prior import load_prior

    source = _source(args)
    trials = parse_trials(args.trials)
    if not 0.0 < args.false_alarm_rate < 1.0:
        raise ConfigError(
            f"--false-alarm-rate must lie between 0 and 1, got {args.false_alarm_rate}"
        )
    output_dir(args.output)
    if any(present(args.output / f) for f in RESULT_FILES) and not args.force:
        raise ConfigError(
            f"--output {args.output}: holds a recognition already (give --force to replace it)"
        )
    by_option = args.table is not None
    kind = input_kind(
        source,
        "--table" if by_option else "DATASET|TABLE",
        prior_option="--prior",
        data_sets=not by_option,
    )
    # The touches are checked before the library is loaded (with scikit-learn): a mistake in
    # them is refused at once.
    if kind == DATASET:
        recorded = _data_set_trials(source, trials)
        library = load_prior(args.prior, "--prior")
        observations = _from_data_set(source, library, trials, recorded)
    else:
        table = _read_table(source, trials)
        library = load_prior(args.prior, "--prior")
        observations = _from_table(table, library, trials)
    try:
        result = library.recognise(observations, false_alarm_rate=args.false_alarm_rate)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    from aptkt import __version__
    from aptkt.experiments.recognition_report import write_recognition

    head = {
        "library": str(args.prior),
        "input": str(source),
        "trials": None if trials is None else str(trials),
        "software_version": __version__,
    }
    written = write_recognition(
        result, args.output, head=head, say=lambda line: print(line, flush=True)
    )
    print(f"written: {', '.join(str(p) for p in written)}")
    return 0


def _source(args: argparse.Namespace) -> Path:
    """The touches' file: DATASET|TABLE, or --table as it was written before."""
    if args.input is not None and args.table is not None:
        raise ConfigError(
            f"{args.input} and --table {args.table}: give the touches once, as DATASET|TABLE"
        )
    source = args.input if args.input is not None else args.table
    if source is None:
        raise ConfigError(
            "give the touches: aptkt recognise --prior PRIOR DATASET|TABLE (a feature table "
            ".csv/.h5, or a data set of this skin)"
        )
    return source


def _chosen(observations: dict, trials: Trials | None, path: Path) -> dict:
    if trials is not None and not any(len(obs) for obs in observations.values()):
        raise ConfigError(
            f"--trials {trials}: {path} has no touches of the library's actions in these trials"
        )
    return observations


def _read_table(path: Path, trials: Trials | None) -> Any:
    """The feature table, checked against the limits and for the chosen trials."""
    from aptkt.experiments.table_limits import read_table_within_limits

    table = read_table_within_limits(path, library=True)
    if len(table.objects) == 0:
        raise ConfigError(f"{path}: holds no rows")
    check_trials(trials, table.trials.tolist(), path)
    return table


def _from_table(table: Any, library: Any, trials: Trials | None) -> dict:
    """The table's observations of the library's actions, checked against the library's
    features: the same modalities, and where the library was built from a table, the same
    columns — missing and extra ones named."""
    import numpy as np

    from aptkt.learning.feature_table import table_columns

    path = table.path
    actions = [a for a in table.action_names if a in library]
    if not actions:
        raise ConfigError(
            f"{path}: none of its actions ({', '.join(table.action_names)}) is in the "
            f"library ({', '.join(library.actions)})"
        )
    recorded = library.metadata.get("feature_table_columns") or {}
    for action in actions:
        have = table_columns(table, action)
        want = recorded.get(action)
        if want is None:  # a library built from a data set: its modalities and their widths
            want_dims = {m: v.shape[1] for m, v in library[action].observations.modalities.items()}
            have_dims = {m: len(c) for m, c in have.items()}
            if have_dims != want_dims:
                raise ConfigError(
                    f"{path}: action {action} has modalities {have_dims}, the library's "
                    f"{want_dims} (another sensor or extraction?)"
                )
            continue
        flat_have = [c for cols in have.values() for c in cols]
        flat_want = [c for cols in want.values() for c in cols]
        missing = [c for c in flat_want if c not in flat_have]
        extra = [c for c in flat_have if c not in flat_want]
        if missing or extra:
            raise ConfigError(
                f"{path}: action {action}'s columns differ from the library's: "
                + "; ".join(
                    part
                    for part in (
                        f"missing {', '.join(missing[:8])}{' ...' if len(missing) > 8 else ''}"
                        if missing
                        else "",
                        f"extra {', '.join(extra[:8])}{' ...' if len(extra) > 8 else ''}"
                        if extra
                        else "",
                    )
                    if part
                )
            )
    rows = np.ones(len(table.objects), dtype=bool) if trials is None else trials.mask(table.trials)
    return _chosen(table.observations(actions, rows), trials, path)


def _data_set_trials(path: Path, trials: Trials | None) -> list[int]:
    """The data set's recorded trials, once the file is checked and holds the chosen ones."""
    from aptkt.commands._checks import intact_data_set

    intact_data_set(path, "DATASET")
    recorded = dataset_trials(path)
    check_trials(trials, recorded, path)
    return recorded


def _from_data_set(path: Path, library: Any, trials: Trials | None, recorded: list[int]) -> dict:
    from aptkt.learning.dataset import load_observations, stored_actions

    actions = [a for a in stored_actions(path) if a in library]
    if not actions:
        raise ConfigError(
            f"{path}: none of its actions is in the library ({', '.join(library.actions)})"
        )
    chosen = None if trials is None else [t for t in recorded if t in trials]
    return _chosen(load_observations(path, actions=actions, trials=chosen), trials, path)
