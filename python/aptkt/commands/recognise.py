"""``aptkt recognise``: which known object each touch is, how sure, or none of them."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from aptkt.commands._checks import input_file, output_dir
from aptkt.errors import ConfigError
from aptkt.files import present

RESULT_FILES = ("predictions.csv", "summary.json")


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
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--table", type=Path, metavar="TABLE", help="feature table (.csv, .h5)")
    src.add_argument(
        "data", type=Path, nargs="?", metavar="DATASET", help="data set (HDF5) of this skin"
    )
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
    from aptkt.experiments.recognition_report import write_recognition

    if not 0.0 < args.false_alarm_rate < 1.0:
        raise ConfigError(
            f"--false-alarm-rate must lie between 0 and 1, got {args.false_alarm_rate}"
        )
    output_dir(args.output)
    if any(present(args.output / f) for f in RESULT_FILES) and not args.force:
        raise ConfigError(
            f"--output {args.output}: holds a recognition already (give --force to replace it)"
        )
    library = load_prior(args.prior, "--prior")
    if args.table is not None:
        observations = _from_table(args.table, library)
        source = str(args.table)
    else:
        observations = _from_data_set(args.data, library)
        source = str(args.data)
    try:
        result = library.recognise(observations, false_alarm_rate=args.false_alarm_rate)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    from aptkt import __version__

    head = {"library": str(args.prior), "input": source, "software_version": __version__}
    written = write_recognition(
        result, args.output, head=head, say=lambda line: print(line, flush=True)
    )
    print(f"written: {', '.join(str(p) for p in written)}")
    return 0


def _from_table(path: Path, library: Any) -> dict:
    """The table's observations of the library's actions, checked against the library's
    features: the same modalities, and where the library was built from a table, the same
    columns — missing and extra ones named."""
    import numpy as np

    from aptkt.experiments.table_limits import read_table_within_limits
    from aptkt.learning.feature_table import table_columns

    input_file(path, "--table")
    table = read_table_within_limits(path, library=True)
    if len(table.objects) == 0:
        raise ConfigError(f"--table {path}: holds no rows")
    actions = [a for a in table.action_names if a in library]
    if not actions:
        raise ConfigError(
            f"--table {path}: none of its actions ({', '.join(table.action_names)}) is in the "
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
                    f"--table {path}: action {action} has modalities {have_dims}, the library's "
                    f"{want_dims} (another sensor or extraction?)"
                )
            continue
        flat_have = [c for cols in have.values() for c in cols]
        flat_want = [c for cols in want.values() for c in cols]
        missing = [c for c in flat_want if c not in flat_have]
        extra = [c for c in flat_have if c not in flat_want]
        if missing or extra:
            raise ConfigError(
                f"--table {path}: action {action}'s columns differ from the library's: "
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
    return table.observations(actions, np.ones(len(table.objects), dtype=bool))


def _from_data_set(path: Path, library: Any) -> dict:
    from aptkt.commands._checks import intact_data_set
    from aptkt.learning.dataset import load_observations, stored_actions

    input_file(path, "DATASET")
    intact_data_set(path, "DATASET")
    actions = [a for a in stored_actions(path) if a in library]
    if not actions:
        raise ConfigError(
            f"{path}: none of its actions is in the library ({', '.join(library.actions)})"
        )
    return load_observations(path, actions=actions)
