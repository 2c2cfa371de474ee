"""What the commands that read observations read, given the same way to each: one positional
``DATASET|TABLE`` (a data set of this skin, or a feature table of any sensor, told apart by what
the file holds, not by an option), and ``--trials``, the trial numbers to read of it.

``--trials`` takes trial numbers and inclusive ranges, comma-separated: ``3``, ``25-49``,
``0-9,20-29``. ``FIRST:STOP`` (STOP not included, ``0:25`` is ``0-24``) is read too: it was
``prior build``'s spelling, and scripts use it.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aptkt.commands._checks import input_file
from aptkt.errors import ConfigError

#: The kinds of input, as :func:`input_kind` names them.
TABLE = "table"
DATASET = "dataset"

#: How --trials is written, for help texts and messages.
TRIALS_SYNTAX = "trial numbers and ranges, e.g. 3, 25-49 or 0-9,20-29"

_ITEM = re.compile(r"^(\d+)(?:([-:])(\d+))?$")


def add_trials_option(parser, what: str = "rows or recordings") -> None:
    """``--trials TRIALS``, the same wherever a table or a data set is read."""
    parser.add_argument(
        "--trials",
        metavar="TRIALS",
        help=f"only the {what} of these trials: {TRIALS_SYNTAX} (ranges include both ends; "
        "default: every trial)",
    )


@dataclass(frozen=True)
class Trials:
    """A set of trial numbers held as sorted, disjoint, inclusive ranges (``0-2000000000`` is
    two numbers, not two billion)."""

    ranges: tuple[tuple[int, int], ...]

    def __str__(self) -> str:
        return ",".join(str(a) if a == b else f"{a}-{b}" for a, b in self.ranges)

    def __contains__(self, trial: object) -> bool:
        return isinstance(trial, (int, np.integer)) and any(a <= trial <= b for a, b in self.ranges)

    def mask(self, trials: np.ndarray) -> np.ndarray:
        """Which of ``trials`` are chosen."""
        trials = np.asarray(trials)
        chosen = np.zeros(trials.shape, dtype=bool)
        for a, b in self.ranges:
            chosen |= (trials >= a) & (trials <= b)
        return chosen

    def missing(self, available: Iterable[int]) -> Trials:
        """The chosen numbers that are not among ``available``."""
        have = sorted({int(t) for t in available})
        gaps: list[tuple[int, int]] = []
        for a, b in self.ranges:
            start = a
            for t in have:
                if t > b:
                    break
                if t >= start:
                    if t > start:
                        gaps.append((start, t - 1))
                    start = t + 1
            if start <= b:
                gaps.append((start, b))
        return Trials(tuple(gaps))


def trials_of(numbers: Iterable[int]) -> Trials:
    """The ranges of a set of trial numbers: ``trials_of([0, 1, 2, 5])`` is ``0-2,5``."""
    ranges: list[tuple[int, int]] = []
    for t in sorted({int(n) for n in numbers}):
        if ranges and t == ranges[-1][1] + 1:
            ranges[-1] = (ranges[-1][0], t)
        else:
            ranges.append((t, t))
    return Trials(tuple(ranges))


def parse_trials(text: str | None, option: str = "--trials") -> Trials | None:
    """``--trials`` as written (None: not given): every mistake a one-line ConfigError naming
    the option, the value and how to write it."""
    if text is None:
        return None
    from aptkt.data.schema import MAX_TRIAL_NUMBER  # (aptkt.data loads h5py: not at start-up)

    said = f"{option} {text}"
    items = [item.strip() for item in text.split(",")]
    if not any(items):
        raise ConfigError(f"{option}: give {TRIALS_SYNTAX}")
    ranges: list[tuple[int, int]] = []
    for item in items:
        m = _ITEM.match(item)
        if m is None:
            what = "an empty item" if not item else repr(item)
            raise ConfigError(
                f"{said}: {what} is not a trial number or a range; give {TRIALS_SYNTAX}"
            )
        first = int(m[1])
        last = first if m[2] is None else int(m[3]) - (m[2] == ":")
        if m[2] == ":" and last < first:
            raise ConfigError(
                f"{said}: {item} holds no trial (FIRST:STOP stops before STOP; FIRST-LAST "
                "includes both ends)"
            )
        if last < first:
            raise ConfigError(f"{said}: the range {item} runs backwards (write {last}-{first})")
        if last > MAX_TRIAL_NUMBER:
            raise ConfigError(
                f"{said}: trial numbers stop at {MAX_TRIAL_NUMBER} (a data set stores them as "
                "32-bit integers)"
            )
        ranges.append((first, last))
    merged: list[tuple[int, int]] = []
    for a, b in sorted(ranges):
        if merged and a <= merged[-1][1] + 1:
            merged[-1] = (merged[-1][0], max(b, merged[-1][1]))
        else:
            merged.append((a, b))
    return Trials(tuple(merged))


def check_trials(chosen: Trials | None, available: Iterable[int], source: str | Path) -> None:
    """Every chosen trial is one of the input's: a number that is not is a typing mistake, or
    the wrong file, and reading fewer touches than asked for without a word would hide it."""
    if chosen is None:
        return
    have = {int(t) for t in available}
    absent = chosen.missing(have)
    if absent.ranges:
        which = "" if absent == chosen else f" trial(s) {absent}"
        raise ConfigError(
            f"--trials {chosen}:{which} not in {source} (it has trials "
            f"{str(trials_of(have)) or 'none'})"
        )


def input_kind(
    path: str | Path,
    option: str = "DATASET|TABLE",
    prior_option: str | None = None,
    *,
    data_sets: bool = True,
) -> str:
    """:data:`TABLE` or :data:`DATASET`, by what the file is: a feature table is a .csv file, or
    an HDF5 file of columns (1-D data sets at its root); a data set of this skin is an HDF5 file
    of groups. Anything else is one line saying what to give (a library file: where it goes,
    ``prior_option``, if the command takes one; a data set only where ``data_sets``). An
    unreadable .h5 file counts as a data set: the data set reader says what is wrong with it."""
    kind = _kind(path, option, prior_option, data_sets)
    return DATASET if kind == _UNREADABLE_HDF5 else kind


# What _kind calls a .h5 file that HDF5 cannot open (empty, cut short, damaged).
_UNREADABLE_HDF5 = "unreadable HDF5"


def _kind(path: str | Path, option: str, prior_option: str | None, data_sets: bool) -> str:
    import h5py

    from aptkt.learning.feature_table import is_feature_table

    if not os.path.lexists(path):  # (os.path: a name too long to exist is an answer too)
        raise ConfigError(f"{path}: no such data set or feature table")
    path = input_file(path, option)
    if path.suffix.lower() == ".npz":
        where = f"give it with {prior_option}, and " if prior_option else ""
        raise ConfigError(
            f"{path}: is a prior-knowledge file (.npz); {where}as {option} give "
            + (
                "a data set (HDF5) or a feature table (.csv, .h5)"
                if data_sets
                else "a feature table (.csv, .h5)"
            )
        )
    if is_feature_table(path):
        return TABLE
    try:
        with h5py.File(path, "r") as f:
            members = list(f.values())
    except (OSError, ValueError):
        if path.suffix.lower() in (".h5", ".hdf5"):
            return _UNREADABLE_HDF5
        raise ConfigError(
            f"{path}: is neither a feature table (.csv, or HDF5 columns object, action, trial, "
            "<modality>.<k>) nor a data set (HDF5) of aptkt"
        ) from None
    if members and all(isinstance(m, h5py.Dataset) for m in members):
        return TABLE  # columns without an object column: the table reader names what is missing
    return DATASET


def refuse_data_set(
    path: str | Path, command: str, option: str = "TABLE", prior_option: str | None = None
) -> None:
    """A command that reads only feature tables, given a data set: one line saying how to
    write its table (the features of this skin, as this package extracts them)."""
    kind = _kind(path, option, prior_option, data_sets=False)
    if kind == _UNREADABLE_HDF5:
        raise ConfigError(
            f"{path}: is not a readable HDF5 file (damaged or cut short?); {command} reads "
            "a feature table (.csv, .h5)"
        )
    if kind == DATASET:
        name = Path(path)
        raise ConfigError(
            f"{path}: is a data set of this skin; {command} reads a feature table: write one with "
            f"'aptkt dataset export-features {name} -o {name.with_suffix('.csv')}'"
        )


def dataset_trials(path: str | Path) -> list[int]:
    """The trial numbers of a data set's recordings."""
    from aptkt.data import DatasetReader

    with DatasetReader(path) as rd:
        return sorted({int(k[2]) for k in rd.keys()})
