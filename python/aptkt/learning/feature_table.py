"""Feature tables: the observations of any sensor as one row per observation (CSV or HDF5).

Columns: ``object``, ``action``, ``trial``, then one column per feature dimension named
``<modality>.<k>`` with k = 0, 1, ... (``force.0``, ``thermal.0`` ... ``thermal.9``). An action
has the modalities whose columns are filled on its rows; a column an action does not have stays
empty on that action's rows (an empty CSV cell, NaN in HDF5), and the dimensions an action uses
of a modality are ``.0`` up to some ``.d-1``. HDF5 files hold one 1-D data set per column at
the file's root (strings for ``object`` and ``action``).

An optional column ``extraction`` names what computed the features, the same on every row:
``aptkt-skin`` (:data:`~aptkt.learning.pipeline.SKIN_EXTRACTION`), written by ``aptkt dataset
export-features``, says they are this skin's features as this package extracts them, so that
learning from the table transforms them as it would the data set's (log of the texture's
activities, thermal PCA). Without it, or with another name, every column is z-scored as it is.

Every problem is reported as a :class:`~aptkt.errors.FeatureTableError` naming the file, the row
(numbered from 1, the header not counted) and the column — a table is usually written by another
program, and its author needs to find the bad cell.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from aptkt.data.schema import MAX_TRIAL_NUMBER
from aptkt.errors import FeatureTableError
from aptkt.files import open_atomically, replaced_atomically
from aptkt.learning.observations import Observations, ObservationTable, common_extraction
from aptkt.names import name_problem

__all__ = [
    "ID_COLUMNS",
    "EXTRACTION_COLUMN",
    "FeatureTable",
    "read_feature_table",
    "table_from_columns",
    "split_held_out",
    "write_feature_table",
    "check_table_name",
]

ID_COLUMNS = ("object", "action", "trial")
#: The optional column naming what computed the features (one name for every row).
EXTRACTION_COLUMN = "extraction"
_FEATURE = re.compile(r"^([A-Za-z_][A-Za-z0-9_-]*)\.(0|[1-9][0-9]*)$")
_CSV = (".csv",)
_HDF5 = (".h5", ".hdf5")


@dataclass
class FeatureTable:
    """A validated feature table: ``values`` is (rows, feature columns), NaN where empty."""

    path: Path
    objects: np.ndarray
    actions: np.ndarray
    trials: np.ndarray
    columns: list[str]
    values: np.ndarray
    #: What computed the features (the ``extraction`` column), None if the table does not say.
    extraction: str | None = None

    def _error(self, msg: str, row: int | None = None, column: str | None = None):
        return _error(self.path, msg, row, column)

    @property
    def action_names(self) -> list[str]:
        return list(dict.fromkeys(self.actions.tolist()))

    @property
    def object_names(self) -> list[str]:
        return list(dict.fromkeys(self.objects.tolist()))

    def take(self, rows: np.ndarray) -> FeatureTable:
        """The table of the rows of a boolean mask (or of indices), in their order: a choice of
        trials, say. (Rows are validated per action, so any choice of them is a valid table.)"""
        return FeatureTable(
            self.path,
            self.objects[rows],
            self.actions[rows],
            self.trials[rows],
            list(self.columns),
            self.values[rows],
            self.extraction,
        )

    def rows_of(self, obj: str, action: str) -> np.ndarray:
        """0-based indices of the rows of one object and action."""
        return np.flatnonzero((self.objects == obj) & (self.actions == action))

    def observations(
        self, actions: Sequence[str] | None = None, rows: np.ndarray | None = None
    ) -> dict[str, Observations]:
        """The observation table of the chosen actions, restricted to a boolean row mask."""
        names = list(actions) if actions is not None else self.action_names
        unknown = [a for a in names if a not in set(self.action_names)]
        if unknown:
            raise self._error(
                f"no rows of action(s) {', '.join(unknown)}; "
                f"the table has {', '.join(self.action_names)}"
            )
        table = {}
        for action in names:
            mask = self.actions == action
            if rows is not None:
                mask &= rows
            mods = {
                m: self.values[np.ix_(mask, cols)] for m, cols in self._modalities(action).items()
            }
            table[action] = Observations(
                action, mods, self.objects[mask], self.trials[mask], self.extraction
            )
        return table

    def _modalities(self, action: str) -> dict[str, list[int]]:
        """Column indices of each modality the action has (validated on reading)."""
        rows = np.flatnonzero(self.actions == action)
        filled = ~np.isnan(self.values[rows[0]])
        mods: dict[str, list[int]] = {}
        for c, name in enumerate(self.columns):  # sorted by modality, then dimension
            if filled[c]:
                mods.setdefault(_split(name)[0], []).append(c)
        return mods


def _error(path: Path, msg: str, row: int | None = None, column: str | None = None):
    where = str(path)
    if row is not None:
        where += f", row {row + 1}"
    if column is not None:
        where += f", column {column}"
    return FeatureTableError(f"{where}: {msg}")


def _split(column: str) -> tuple[str, int]:
    m = _FEATURE.match(column)
    assert m is not None
    return m.group(1), int(m.group(2))


def read_feature_table(path: str | Path) -> FeatureTable:
    """Read and validate a CSV or HDF5 feature table (see the module's documentation)."""
    path = Path(path)
    if path.suffix.lower() not in _CSV + _HDF5:
        raise _error(path, "a feature table is a .csv or an HDF5 (.h5, .hdf5) file")
    if not path.is_file():
        raise _error(path, "no such file")
    header, cells = _read_csv(path) if path.suffix.lower() in _CSV else _read_hdf5(path)
    return _validate(path, header, cells)


def table_from_columns(columns: Mapping[str, Sequence], name: str = "<columns>") -> FeatureTable:
    """Validate a feature table held in memory: column name -> values (one per row), named as
    in a file (``object``, ``action``, ``trial``, ``<modality>.<k>``; NaN where empty). ``name``
    stands for the file in messages."""
    path = Path(name)
    cells: dict[str, list] = {str(k): list(v) for k, v in columns.items()}
    lengths = {len(v) for v in cells.values()}
    if len(lengths) > 1:
        raise _error(path, "the columns have different lengths: " + _lengths(cells))
    return _validate(path, list(cells), cells)


def _read_csv(path: Path) -> tuple[list[str], dict[str, list]]:
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            header = [h.strip() for h in next(reader, [])]
            rows = list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise _error(path, f"cannot read the CSV file: {exc}") from None
    if not header:
        raise _error(path, "the file is empty (expected a header row)")
    rows = [r for r in rows if any(cell.strip() for cell in r)]
    for i, r in enumerate(rows):
        if len(r) != len(header):
            raise _error(path, f"{len(r)} cells, but the header has {len(header)} columns", i)
    return header, {h: [r[j].strip() for r in rows] for j, h in enumerate(header)}


def _read_hdf5(path: Path) -> tuple[list[str], dict[str, list]]:
    try:
        with h5py.File(path, "r") as f:
            for k in f:
                # A link would read another file (or fail inside h5py): a table holds its own
                # columns.
                if isinstance(f.get(k, getlink=True), (h5py.ExternalLink, h5py.SoftLink)):
                    raise _error(
                        path, "is a link; a feature table holds its columns itself", None, k
                    )
            header = [k for k in f if isinstance(f[k], h5py.Dataset)]
            cells: dict[str, list] = {}
            for k in header:
                d = f[k]
                if d.ndim != 1:
                    raise _error(path, f"expected a 1-D data set, got shape {d.shape}", None, k)
                values = d.asstr()[()] if d.dtype.kind in "OS" else d[()]
                cells[k] = list(values)
    except FeatureTableError:
        raise
    except (OSError, KeyError, ValueError) as exc:
        raise _error(path, f"cannot read the HDF5 file: {exc}") from None
    lengths = {len(v) for v in cells.values()}
    if len(lengths) > 1:
        raise _error(path, "the columns have different lengths: " + _lengths(cells))
    return header, cells


def _lengths(cells: Mapping[str, list]) -> str:
    return ", ".join(f"{k} {len(v)}" for k, v in cells.items())


def _validate(path: Path, header: list[str], cells: dict[str, list]) -> FeatureTable:
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise _error(path, f"column(s) {', '.join(dup)} appear more than once")
    missing = [c for c in ID_COLUMNS if c not in header]
    if missing:
        raise _error(
            path,
            f"missing column(s) {', '.join(missing)}; a feature table has the columns "
            "object, action, trial and <modality>.<k>",
        )
    features = [h for h in header if h not in (*ID_COLUMNS, EXTRACTION_COLUMN)]
    for h in features:
        if not _FEATURE.match(h):
            raise _error(
                path,
                "is neither object, action, trial, extraction nor a feature column "
                "<modality>.<k> (e.g. force.0)",
                None,
                repr(h),
            )
    if not features:
        raise _error(path, "no feature columns <modality>.<k>")
    dims: dict[str, list[int]] = {}
    for h in features:
        m, k = _split(h)
        dims.setdefault(m, []).append(k)
    for m, ks in dims.items():
        gap = sorted(set(range(max(ks) + 1)) - set(ks))
        if gap:
            raise _error(path, f"modality {m} has no column {m}.{gap[0]}")
    # Column order: modality by first appearance, then dimension.
    features.sort(key=lambda h: (list(dims).index(_split(h)[0]), _split(h)[1]))
    n = len(cells["object"])
    if n == 0:
        raise _error(path, "no rows")

    objects = np.array([str(v).strip() for v in cells["object"]], dtype=object)
    actions = np.array([str(v).strip() for v in cells["action"]], dtype=object)
    for name, col in (("object", objects), ("action", actions)):
        empty = np.flatnonzero(col == "")
        if empty.size:
            raise _error(path, "empty name", int(empty[0]), name)
        _check_names(path, col, name)
    trials = np.empty(n, dtype=np.int64)
    for i, v in enumerate(cells["trial"]):
        trials[i] = _integer(path, v, i)
    values = np.empty((n, len(features)))
    for c, h in enumerate(features):
        for i, v in enumerate(cells[h]):
            values[i, c] = _number(path, v, i, h)

    extraction = _extraction(path, cells) if EXTRACTION_COLUMN in header else None
    table = FeatureTable(
        path, objects.astype(str), actions.astype(str), trials, features, values, extraction
    )
    _check_rows(table)
    return table


def _check_names(path: Path, names: np.ndarray, column: str) -> None:
    """Every distinct name of a column is a name (:func:`aptkt.names.name_problem`)."""
    first: dict[str, int] = {}
    for i, name in enumerate(names.tolist()):
        first.setdefault(name, i)
    for name, i in first.items():
        why = name_problem(name)
        if why is not None:
            raise _error(path, why, i, column)


def _extraction(path: Path, cells: dict[str, list]) -> str:
    names = [str(v).strip() for v in cells[EXTRACTION_COLUMN]]
    _check_names(path, np.array(names, dtype=object), EXTRACTION_COLUMN)
    for i, name in enumerate(names):
        if name == "":
            raise _error(path, "empty name", i, EXTRACTION_COLUMN)
        if name != names[0]:
            raise _error(
                path,
                f"{name!r}, but {names[0]!r} in row 1: features computed in different ways "
                "cannot be learnt from together",
                i,
                EXTRACTION_COLUMN,
            )
    return names[0]


def _integer(path: Path, v, row: int) -> int:
    try:
        f = float(v)
    except (TypeError, ValueError):
        f = math.nan
    if not math.isfinite(f) or f != int(f):
        raise _error(path, f"{v!r} is not a whole trial number", row, "trial")
    if not 0 <= f <= MAX_TRIAL_NUMBER:
        raise _error(path, f"trial {str(v)[:30]} is not within 0..{MAX_TRIAL_NUMBER}", row, "trial")
    return int(f)


def _number(path: Path, v, row: int, column: str) -> float:
    if isinstance(v, str):
        if v == "":
            return math.nan  # not a feature of this row's action
        try:
            f = float(v)
        except ValueError:
            raise _error(path, f"{v!r} is not a number", row, column) from None
        if not math.isfinite(f):
            raise _error(
                path,
                f"non-finite value {v!r} (leave the cell empty where an action has no such "
                "feature)",
                row,
                column,
            )
        return f
    f = float(v)
    if math.isinf(f):
        raise _error(path, f"non-finite value {f}", row, column)
    return f  # NaN in HDF5: empty


def _check_rows(table: FeatureTable) -> None:
    filled = ~np.isnan(table.values)
    for action in table.action_names:
        rows = np.flatnonzero(table.actions == action)
        first = rows[0]
        differs = np.flatnonzero((filled[rows] != filled[first]).any(axis=1))
        if differs.size:
            r = rows[differs[0]]
            c = int(np.flatnonzero(filled[r] != filled[first])[0])
            state = "empty" if not filled[r, c] else "filled"
            other = "filled" if filled[first, c] else "empty"
            raise table._error(
                f"{state}, but {other} in row {first + 1} of the same action {action} "
                "(every row of an action has the same feature columns)",
                int(r),
                table.columns[c],
            )
        if not filled[first].any():
            raise table._error(f"action {action} has no feature values", int(first))
        used: dict[str, list[int]] = {}
        for col in np.flatnonzero(filled[first]):
            m, k = _split(table.columns[col])
            used.setdefault(m, []).append(k)
        for m, ks in used.items():
            gap = sorted(set(range(max(ks) + 1)) - set(ks))
            if gap:
                raise table._error(
                    f"action {action} uses {m}.{max(ks)} but not {m}.{gap[0]}",
                    int(first),
                    f"{m}.{gap[0]}",
                )
    keys: dict[tuple[str, str, int], int] = {}
    for i, key in enumerate(zip(table.objects, table.actions, table.trials.tolist())):
        if key in keys:
            raise table._error(
                f"object {key[0]}, action {key[1]}, trial {key[2]} also in row {keys[key] + 1}",
                i,
            )
        keys[key] = i


def is_feature_table(path: str | Path) -> bool:
    """Whether ``path`` names a feature table rather than a data set of this skin: a CSV file,
    or an HDF5 file whose top level holds an ``object`` column (a data set's holds groups)."""
    path = Path(path)
    if path.suffix.lower() in _CSV:
        return True
    if path.suffix.lower() not in _HDF5:
        return False
    try:
        with h5py.File(path, "r") as f:
            return isinstance(f.get("object"), h5py.Dataset)
    except OSError:
        return False


def table_columns(table: FeatureTable, action: str) -> dict[str, list[str]]:
    """The feature columns of each modality of ``action``, by name."""
    return {m: [table.columns[c] for c in cols] for m, cols in table._modalities(action).items()}


def check_table_name(path: str | Path) -> Path:
    """A feature table's file name: its suffix says the format."""
    path = Path(path)
    if path.suffix.lower() not in _CSV + _HDF5:
        raise _error(path, "a feature table is a .csv or an HDF5 (.h5, .hdf5) file")
    return path


def write_feature_table(
    path: str | Path, table: ObservationTable, *, extraction: str | None = None
) -> Path:
    """Write an observation table as a feature table (CSV or HDF5, by the file's suffix);
    ``extraction`` fills the ``extraction`` column (e.g.
    :data:`~aptkt.learning.pipeline.SKIN_EXTRACTION` for this skin's features as this package
    extracts them); None: what the observations say (no column if they say nothing)."""
    path = check_table_name(path)
    if extraction is None:
        extraction = common_extraction(table.values())
    suffix = path.suffix.lower()
    widths: dict[str, int] = {}
    for obs in table.values():
        for m, v in obs.modalities.items():
            widths[m] = max(widths.get(m, 0), v.shape[1])
    columns = [f"{m}.{k}" for m, d in widths.items() for k in range(d)]
    objects, actions, trials, blocks = [], [], [], []
    for name, obs in table.items():
        block = np.full((len(obs), len(columns)), np.nan)
        for m, v in obs.modalities.items():
            start = columns.index(f"{m}.0")
            block[:, start : start + v.shape[1]] = v
        objects += obs.objects.tolist()
        actions += [name] * len(obs)
        trials += obs.trials.tolist()
        blocks.append(block)
    values = np.vstack(blocks) if blocks else np.zeros((0, len(columns)))
    marker = [] if extraction is None else [EXTRACTION_COLUMN]
    if suffix in _CSV:
        with open_atomically(path, FeatureTableError, newline="") as fh:
            w = csv.writer(fh)
            w.writerow([*ID_COLUMNS, *marker, *columns])
            mark = [] if extraction is None else [extraction]
            for o, a, t, row in zip(objects, actions, trials, values):
                cells = ("" if math.isnan(x) else repr(float(x)) for x in row)
                w.writerow([o, a, t, *mark, *cells])
    else:
        with (
            replaced_atomically(path, FeatureTableError) as tmp,
            h5py.File(tmp, "w", track_order=True) as f,
        ):
            f.create_dataset(
                "object", data=np.array(objects, dtype=object), dtype=h5py.string_dtype()
            )
            f.create_dataset(
                "action", data=np.array(actions, dtype=object), dtype=h5py.string_dtype()
            )
            f.create_dataset("trial", data=np.asarray(trials, dtype=np.int64))
            if extraction is not None:
                f.create_dataset(
                    EXTRACTION_COLUMN,
                    data=np.array([extraction] * len(objects), dtype=object),
                    dtype=h5py.string_dtype(),
                )
            for c, name in enumerate(columns):
                f.create_dataset(name, data=values[:, c])
    return path


def split_held_out(
    table: FeatureTable,
    actions: Sequence[str],
    objects: Sequence[str],
    *,
    test_trials: Iterable[int] | None = None,
    test_fraction: float = 0.5,
) -> tuple[np.ndarray, np.ndarray]:
    """Boolean row masks (pool, test) of the new objects' observations.

    With ``test_trials`` the rows of those trial numbers are held out; otherwise, per action and
    object, the ``test_fraction`` of its rows with the highest trial numbers (at least one).
    Every (action, object) must keep at least one row to learn from and one held out.
    """
    pool = np.zeros(len(table.trials), dtype=bool)
    test = np.zeros_like(pool)
    chosen = None if test_trials is None else {int(t) for t in test_trials}
    for action in actions:
        for obj in objects:
            rows = table.rows_of(obj, action)
            if rows.size < 2:
                listed = ", ".join(str(r + 1) for r in rows) or "none"
                raise _error(
                    table.path,
                    f"object {obj} has {rows.size} row(s) of action {action} (rows: {listed}); "
                    "learning needs at least 2: one to learn from, one held out",
                )
            rows = rows[np.argsort(table.trials[rows], kind="stable")]
            if chosen is None:
                k = min(rows.size - 1, max(1, round(test_fraction * rows.size)))
                held = np.zeros(rows.size, dtype=bool)
                held[rows.size - k :] = True
            else:
                held = np.isin(table.trials[rows], list(chosen))
            if held.all() or not held.any():
                side = "to learn from" if held.all() else "held out"
                raise _error(
                    table.path,
                    f"object {obj}, action {action}: no row left {side} with the chosen test "
                    "trials",
                )
            test[rows[held]] = True
            pool[rows[~held]] = True
    return pool, test
