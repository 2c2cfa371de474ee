"""What a feature table may hold for ``aptkt benchmark`` and ``aptkt learn --table`` (and
:func:`aptkt.experiments.own_data.compare_on_data`): its size against what they can do, checked
before any work starts, and every value a number their statistics keep finite.

A table comes from another program, and nothing bounded it: a table of 10⁶ feature columns
made the reader compare every column's name with every other's, one of 10⁵ objects made the
benchmark compare every object's rows with every other's, and neither printed anything for
minutes. Now the file's size, its header and its lines are checked before it is parsed, then
the table read against the limits below; each message names the limit and why it is one.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from aptkt.errors import FeatureTableError
from aptkt.features import MAX_MAGNITUDE
from aptkt.files import open_regular
from aptkt.learning.feature_table import ID_COLUMNS, FeatureTable, read_feature_table

__all__ = [
    "MAX_TABLE_BYTES",
    "MAX_ROWS",
    "MAX_FEATURE_COLUMNS",
    "MAX_CELLS",
    "MAX_OBJECTS",
    "MAX_LIBRARY_OBJECTS",
    "MAX_LIBRARY_ROWS",
    "MAX_GP_ROWS",
    "MAX_DISTANCE_CELLS",
    "check_size",
    "check_table_file",
    "check_table",
    "read_table_within_limits",
]

#: Largest table file read.
MAX_TABLE_BYTES = 512 << 20
#: Most rows (observations): each is a trial on a robot, and 10⁵ is fifty times the paper's
#: test set.
MAX_ROWS = 100_000
#: Most feature columns: the pipeline whitens and projects each modality with matrices of
#: columns × columns, and the kernels compare every column of every two rows. A tactile
#: feature vector has tens of columns (the BioTac set's 27).
MAX_FEATURE_COLUMNS = 1_000
#: Most cells (rows × columns): the reader checks each one.
MAX_CELLS = 10_000_000
#: Most objects a learning task or a benchmark draws from: every object is a class of its own.
MAX_OBJECTS = 1_000
#: Most rows and objects of a library (``prior build``, ``recognise``): its model of its objects
#: is fitted on a sample of them and on each one's neighbours (GPSettings.library_model
#: "local"), and what grows with it are sums over its rows; :data:`MAX_CELLS` bounds the rows
#: read as before.
MAX_LIBRARY_ROWS = 1_000_000
MAX_LIBRARY_OBJECTS = 100_000
#: Most rows one Gaussian process is fitted on — prior knowledge's model of one action, fitted
#: on all the prior objects' rows of it with ``--library-model exact`` (the local model's fits
#: are bounded by :mod:`aptkt.learning.locality`). Its cost grows with the cube of the rows: 2,000 rows
#: take about half a minute per fit on one core (1,200: 5 s), and the benchmark fits one per
#: group and way of choosing the priors.
MAX_GP_ROWS = 2_000
#: Most entries of the benchmark's comparison of every two objects' mean observations
#: (objects × objects × feature columns of an action): 5·10⁷ take 400 MB.
MAX_DISTANCE_CELLS = 50_000_000

_HEADER_MAX_BYTES = 1 << 20
_CSV = (".csv",)
_HDF5 = (".h5", ".hdf5")


def _fail(path: Path, message: str) -> FeatureTableError:
    return FeatureTableError(f"{path}: {message}")


def check_table_file(path: str | Path, library: bool = False) -> None:
    """The file's size, columns and rows within the limits, from its header and its lines (a
    CSV file) or its data sets' shapes (HDF5), before it is parsed. What else is wrong with it
    is left to the reader, whose messages name the row and column."""
    path = Path(path)
    if path.suffix.lower() not in _CSV + _HDF5 or not os.path.lexists(path):
        return  # the reader's message says what a table is, or that there is none
    with open_regular(path, MAX_TABLE_BYTES, FeatureTableError, "a feature table") as fh:
        if path.suffix.lower() in _CSV:
            header = fh.readline(_HEADER_MAX_BYTES + 1)
            if len(header) > _HEADER_MAX_BYTES:
                # Far more columns than any table may have: counted, not kept.
                commas = header.count(b",")
                while not header.endswith(b"\n") and (header := fh.readline(1 << 20)):
                    commas += header.count(b",")
                raise _fail(
                    path,
                    f"{commas + 1 - len(ID_COLUMNS)} feature columns, more than the "
                    f"{MAX_FEATURE_COLUMNS} aptkt learns from (its header is "
                    f"{_HEADER_MAX_BYTES // 1024} kB and more)",
                )
            try:
                columns = len(next(csv.reader([header.decode("utf-8-sig", errors="replace")]), []))
            except csv.Error:
                return  # not a CSV header (a stray carriage return...): the reader says so
            rows = 0
            while chunk := fh.read(1 << 20):
                rows += chunk.count(b"\n")
            rows += bool(chunk) and not chunk.endswith(b"\n")
        else:
            try:
                with h5py.File(fh, "r") as f:
                    shapes = [d.shape for d in f.values() if isinstance(d, h5py.Dataset)]
            except (OSError, ValueError):
                return  # not HDF5: the reader says so
            columns = len(shapes)
            rows = max((s[0] if s else 0 for s in shapes), default=0)
    check_size(path, rows, columns - len(ID_COLUMNS), "lines of rows", library=library)


def check_size(
    path: str | Path, rows: int, features: int, what: str = "rows", library: bool = False
) -> None:
    """``rows`` and ``features`` (feature columns) within the limits (a library's, with
    ``library``); ``path`` names the table in the message, ``what`` the rows."""
    path = Path(path)
    if features > MAX_FEATURE_COLUMNS:
        raise _fail(
            path,
            f"{features} feature columns, more than the {MAX_FEATURE_COLUMNS} aptkt learns from "
            "(each modality is whitened with a matrix of columns × columns)",
        )
    most = MAX_LIBRARY_ROWS if library else MAX_ROWS
    if rows > most:
        whom = "a library holds" if library else "aptkt learns from"
        raise _fail(path, f"{rows} {what}, more than the {most} rows {whom}")
    if rows * max(features, 1) > MAX_CELLS:
        raise _fail(
            path,
            f"{rows} rows × {features} feature columns = {rows * features} cells, more than the "
            f"{MAX_CELLS} aptkt reads from a table",
        )


def check_table(
    table: FeatureTable,
    *,
    actions: Sequence[str] | None = None,
    prior_objects: Sequence[str] | None = None,
    priors_per_group: int | None = None,
    library: bool = False,
    exact: bool = False,
) -> None:
    """The table read against the limits: rows, columns, objects, every value within
    ±:data:`aptkt.features.MAX_MAGNITUDE` (the first beyond named by row and column), and the
    rows the prior's Gaussian process is fitted on for each of ``actions`` (all by default):
    those of ``prior_objects`` (``learn --table``), or, for the benchmark, the first half of the
    ``priors_per_group`` objects with the most rows, together with its comparison of every
    two objects."""
    path = table.path
    check_size(path, len(table.trials), len(table.columns), library=library)
    objects = table.object_names
    most = MAX_LIBRARY_OBJECTS if library else MAX_OBJECTS
    if len(objects) > most:
        raise _fail(
            path,
            f"{len(objects)} objects, more than the {most} "
            + (
                "a library holds" if library else "aptkt learns (each object is a class of its own)"
            ),
        )
    with np.errstate(invalid="ignore"):
        huge = np.abs(table.values) > MAX_MAGNITUDE
    if huge.any():
        row, column = (int(i) for i in np.argwhere(huge)[0])
        raise _fail(
            path,
            f"row {row + 1}, column {table.columns[column]}: {table.values[row, column]:g} is "
            f"beyond ±{MAX_MAGNITUDE:g}; no sensor's feature is that large, and its square "
            "would overflow the statistics learning computes (scale the column)",
        )
    chosen = list(actions) if actions else table.action_names
    for action in chosen:
        names, counts = np.unique(table.objects[table.actions == action], return_counts=True)
        rows_of = dict(zip(names.tolist(), counts.tolist()))
        if prior_objects is not None:
            fitted = sum(rows_of.get(o, 0) for o in prior_objects)
            who = f"the prior objects {', '.join(prior_objects)}"
        elif priors_per_group is not None:
            largest = sorted(rows_of.values(), reverse=True)[:priors_per_group]
            fitted = sum(n // 2 for n in largest)
            who = f"the first half of {priors_per_group} prior objects"
        else:
            continue
        if exact and fitted > MAX_GP_ROWS:
            raise _fail(
                path,
                f"action {action}: prior knowledge would be fitted on {fitted} rows of {who}, "
                f"more than the {MAX_GP_ROWS} one Gaussian process takes with --library-model "
                "exact (its cost grows with the cube of the rows); use fewer rows or objects, or "
                "--library-model local",
            )
        if priors_per_group is not None:
            first = np.flatnonzero(table.actions == action)
            width = int((~np.isnan(table.values[first[0]])).sum()) if first.size else 0
            cells = len(objects) ** 2 * width
            if cells > MAX_DISTANCE_CELLS:
                raise _fail(
                    path,
                    f"action {action}: {len(objects)} objects × {len(objects)} objects × {width} "
                    f"feature columns = {cells}, more than the {MAX_DISTANCE_CELLS} the "
                    "benchmark's comparison of every two objects takes; use fewer objects or "
                    "columns",
                )


def read_table_within_limits(path: str | Path, settings: Any = None, **limits: Any) -> FeatureTable:
    """The feature table at ``path``, read once its file is within the limits and checked
    against them (:func:`check_table_file`, :func:`check_table`). ``settings``: a benchmark's
    (its actions, its prior objects per group, its library model); ``limits``:
    :func:`check_table`'s keywords."""
    check_table_file(path, library=bool(limits.get("library")))
    table = read_feature_table(path)
    if settings is not None:
        priors = getattr(settings, "prior_objects", None)
        if priors is not None and not isinstance(priors, int):  # (several sizes: the largest)
            priors = max(priors)
        config = getattr(settings, "config", None)
        limits = {
            "actions": getattr(settings, "actions", None),
            "priors_per_group": priors,
            "exact": config is not None and config.gp.library_model == "exact",
            **limits,
        }
    check_table(table, **limits)
    return table
