"""``aptkt benchmark`` and ``aptkt learn --table`` check a table's size (rows, columns, objects)
against what they can do, and its values, before any work: one line naming the limit, within
seconds. ``compare_on_data`` checks every argument."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from aptkt.errors import ConfigError, FeatureTableError
from aptkt.experiments import own_data
from aptkt.experiments.own_data import compare_on_data
from aptkt.experiments.table_limits import (
    MAX_CELLS,
    MAX_DISTANCE_CELLS,
    MAX_FEATURE_COLUMNS,
    MAX_GP_ROWS,
    MAX_OBJECTS,
    MAX_ROWS,
)


def write_csv(path: Path, objects: int, rows_per_object: int, columns: int, value=None) -> Path:
    """``objects`` objects of one action ``a``, each ``rows_per_object`` trials, ``columns``
    feature columns ``f.<k>``; ``value``: put into row 2, column f.1."""
    rng = np.random.default_rng(0)
    # Rows drawn from a few dozen bodies per object centre: the limits are on sizes, and writing
    # millions of distinct cells would cost the test most of its time.
    bodies = [
        [
            ",".join(f"{centre}.{int(x)}" for x in rng.integers(0, 9, size=columns))
            for _ in range(31)
        ]
        for centre in range(7)
    ]
    with path.open("w") as fh:
        fh.write("object,action,trial," + ",".join(f"f.{k}" for k in range(columns)) + "\n")
        for o in range(objects):
            own = bodies[o % 7]
            fh.writelines(f"o{o},a,{t},{own[(o + t) % len(own)]}\n" for t in range(rows_per_object))
    if value is not None:
        lines = path.read_text().splitlines()
        cells = lines[2].split(",")
        cells[4] = value
        lines[2] = ",".join(cells)
        path.write_text("\n".join(lines) + "\n")
    return path


def write_wide_csv(path: Path, objects: int, columns: int) -> Path:
    """The report's table: 10**6 feature columns of 7 objects (37 MB)."""
    ones = ",".join("1" for _ in range(columns))
    with path.open("w") as fh:
        fh.write("object,action,trial," + ",".join(f"f.{k}" for k in range(columns)) + "\n")
        for o in range(objects):
            for t in range(2):
                fh.write(f"o{o},a,{t},{ones}\n")
    return path


def write_wide_h5(path: Path, columns: int) -> Path:
    with h5py.File(path, "w") as f:
        f.create_dataset(
            "object", data=np.array(["a", "a", "b", "b"], dtype=object), dtype=h5py.string_dtype()
        )
        f.create_dataset(
            "action", data=np.array(["p"] * 4, dtype=object), dtype=h5py.string_dtype()
        )
        f.create_dataset("trial", data=np.array([0, 1, 0, 1]))
        for k in range(columns):
            f.create_dataset(f"f.{k}", data=np.arange(4.0))
    return path


CASES = {
    "columns": (
        lambda d: write_wide_csv(d / "wide.csv", 7, 10**6),
        f"1000000 feature columns, more than the {MAX_FEATURE_COLUMNS}",
    ),
    "columns (HDF5)": (
        lambda d: write_wide_h5(d / "wide.h5", MAX_FEATURE_COLUMNS + 1),
        f"{MAX_FEATURE_COLUMNS + 1} feature columns, more than the {MAX_FEATURE_COLUMNS}",
    ),
    "rows": (
        lambda d: write_csv(d / "rows.csv", 10**5, 2, 3),
        f"200000 lines of rows, more than the {MAX_ROWS} rows",
    ),
    "objects": (
        lambda d: write_csv(d / "objects.csv", MAX_OBJECTS + 1, 2, 2),
        f"{MAX_OBJECTS + 1} objects, more than the {MAX_OBJECTS}",
    ),
    "cells": (
        lambda d: write_csv(d / "cells.csv", 25, 800, 600),
        f"more than the {MAX_CELLS} aptkt reads",
    ),
    "huge value": (
        lambda d: write_csv(d / "huge.csv", 8, 8, 3, value="1e308"),
        "row 2, column f.1: 1e+308 is beyond ±1e+100",
    ),
}
BENCHMARK_ONLY = {
    "prior rows": (
        lambda d: write_csv(d / "gp.csv", 5, 1400, 2),
        f"fitted on 2100 rows of the first half of 3 prior objects, more than the {MAX_GP_ROWS}",
    ),
    "distances": (
        lambda d: write_csv(d / "distances.csv", 1000, 2, 60),
        f"1000 objects × 1000 objects × 60 feature columns = 60000000, more than the "
        f"{MAX_DISTANCE_CELLS}",
    ),
}
LEARN_ONLY = {
    "prior rows": (
        lambda d: write_csv(d / "gp.csv", 5, 1100, 2),
        f"fitted on 2200 rows of the prior objects o0, o1, more than the {MAX_GP_ROWS}",
    ),
}


def aptkt(*argv: str, timeout: float = 120.0) -> tuple[int, str, float]:
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "aptkt.cli", *argv],
        capture_output=True,
        text=True,
        timeout=timeout,  # the report: no output in 300 s
    )
    return proc.returncode, proc.stderr, time.monotonic() - t0


def _refused(rc: int, err: str, fragment: str, command: str) -> None:
    assert rc == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"aptkt {command}: error:") and fragment in lines[0], lines[0]


@pytest.mark.parametrize("case", [*CASES, *(f"benchmark: {k}" for k in BENCHMARK_ONLY)])
def test_the_benchmark_refuses_a_table_beyond_its_limits_up_front(tmp_path, case):
    make, fragment = {**CASES, **{f"benchmark: {k}": v for k, v in BENCHMARK_ONLY.items()}}[case]
    table = make(tmp_path)
    out = tmp_path / "out"
    # The Gaussian process over every prior row is the exact library model's.
    exact = ["--library-model", "exact"] if case == "benchmark: prior rows" else []
    rc, err, _ = aptkt("benchmark", str(table), "-o", str(out), "-j", "1", "--no-progress", *exact)
    _refused(rc, err, fragment, "benchmark")
    assert not out.exists()


@pytest.mark.parametrize("case", [*CASES, *(f"learn: {k}" for k in LEARN_ONLY)])
def test_learn_table_refuses_a_table_beyond_its_limits_up_front(tmp_path, case):
    make, fragment = {**CASES, **{f"learn: {k}": v for k, v in LEARN_ONLY.items()}}[case]
    table = make(tmp_path)
    out = tmp_path / "out"
    argv = ["learn", "--table", str(table), "--prior-objects", "o0,o1", "--objects", "o2,o3"]
    exact = ["--library-model", "exact"] if case == "learn: prior rows" else []
    rc, err, _ = aptkt(*argv, "-o", str(out), *exact)
    _refused(rc, err, fragment, "learn")
    assert not out.exists()


def test_a_local_library_takes_prior_rows_beyond_one_exact_fit():
    """The row limit of one Gaussian process binds the exact library model only: the local
    model's fits are bounded whatever the library holds."""
    from aptkt.experiments.table_limits import check_table
    from aptkt.learning.feature_table import read_feature_table

    with tempfile.TemporaryDirectory() as d:
        table = read_feature_table(write_csv(Path(d) / "gp.csv", 5, 1100, 2))
        check_table(table, prior_objects=["o0", "o1"])
        with pytest.raises(FeatureTableError, match="library-model exact"):
            check_table(table, prior_objects=["o0", "o1"], exact=True)


def test_a_table_within_the_limits_is_checked_in_a_moment(tmp_path):
    """The checks themselves cost little: a table just within them is read and checked."""
    from aptkt.experiments.table_limits import read_table_within_limits

    table = write_csv(tmp_path / "t.csv", 50, 40, 200)  # 2,000 rows x 200 columns
    t0 = time.perf_counter()
    read_table_within_limits(table, prior_objects=["o0", "o1"])
    assert time.perf_counter() - t0 < 30


# -- compare_on_data: every argument -------------------------------------------------------------
def _data():
    rng = np.random.default_rng(1)
    objects = np.repeat([f"o{k}" for k in range(5)], 6)
    return {
        "object": objects.tolist(),
        "action": ["a"] * objects.size,
        "trial": np.tile(np.arange(6), 5).tolist(),
        "x": (np.repeat(np.arange(5.0), 6) + rng.normal(size=objects.size)).tolist(),
    }


GOOD = dict(prior_objects=["o0", "o1"], new_objects=["o2", "o3"], modalities={"m": ["x"]})
BAD = [
    ("test_fraction", 2.0),  # the report: returned a result
    ("test_fraction", 0.0),
    ("test_fraction", 1.0),
    ("test_fraction", float("nan")),
    ("test_fraction", True),
    ("test_fraction", "half"),
    ("prior_objects", "o0"),  # a string: its letters would be the objects
    ("prior_objects", ["o0"]),
    ("prior_objects", ["o0", "o0"]),
    ("prior_objects", ["o0", 1]),
    ("prior_objects", None),
    ("new_objects", []),
    ("new_objects", ["o2", ""]),
    ("modalities", {}),
    ("modalities", {"m": []}),
    ("modalities", {"m": [1]}),
    ("modalities", ["x"]),
    ("actions", "a"),
    ("actions", []),
    ("object_column", None),
    ("object_column", 3),
    ("action_column", 3),
    ("trial_column", ["trial"]),
    ("test_trials", "5"),
    ("test_trials", [-1]),
    ("test_trials", [True]),
    ("test_trials", [1.5]),
    ("test_trials", []),
    ("runs", 0),
    ("runs", 1.5),
    ("runs", True),
    ("runs", 10**12),  # (the command line's bound: learn --runs)
    ("budget", 10**12),
    ("patience", 10**12),
    ("test_trials", [10**30]),
    ("config", {"budget": 2}),
    ("output", 5),
    ("say", "print"),
    ("force", "yes"),
    ("budget", -1),
    ("budjet", 2),  # a misspelt learner setting
    ("seed", "x"),
]


@pytest.mark.parametrize("name,value", BAD, ids=[f"{n}={v!r}" for n, v in BAD])
def test_compare_on_data_checks_every_argument_before_any_work(monkeypatch, name, value):
    def never(*args, **kwargs):
        raise AssertionError("the comparison ran")

    monkeypatch.setattr(own_data, "compare_on_table", never)
    with pytest.raises((ConfigError, TypeError)) as err:
        compare_on_data(_data(), **{**GOOD, name: value})
    assert name in str(err.value) or repr(value) in str(err.value) or "learner" in str(err.value)


def test_compare_on_data_refuses_a_value_beyond_the_limit_naming_row_and_column():
    data = _data()
    data["x"][7] = 1e308
    with pytest.raises(FeatureTableError, match="row 8, column m.0: 1e\\+308 is beyond"):
        compare_on_data(data, **GOOD, runs=1, budget=1)


def test_compare_on_data_still_runs_with_good_arguments():
    result = compare_on_data(_data(), **GOOD, runs=1, budget=1, test_fraction=0.5)
    assert set(result.accuracy) == {"APTKT", "APTKT+aux", "baseline"}


@pytest.mark.parametrize("named", [False, True], ids=["columns as named", "modalities"])
def test_compare_on_data_refuses_a_wide_frame_before_building_a_table(named):
    """The table's own checks compare every column with every other: 10**5 columns are
    refused before it is built (they used to take minutes)."""
    data = _data()
    wide = {f"x{k}": data["x"] for k in range(10**5)}
    modalities = {"m": list(wide)} if named else None
    t0 = time.perf_counter()
    with pytest.raises(FeatureTableError, match="100000 feature columns, more than the 1000"):
        compare_on_data(
            {**{k: data[k] for k in ("object", "action", "trial")}, **wide},
            prior_objects=["o0", "o1"],
            new_objects=["o2", "o3"],
            modalities=modalities,
        )
    assert time.perf_counter() - t0 < 30
