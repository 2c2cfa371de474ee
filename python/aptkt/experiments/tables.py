"""Result tables on disk (CSV): every step of every run, and summarised curves."""

from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from aptkt.errors import ConfigError
from aptkt.experiments.aggregate import Curves
from aptkt.files import open_atomically

__all__ = ["write_csv", "read_csv", "curves_rows"]


def write_csv(path: str | Path, rows: Iterable[Mapping[str, Any]]) -> Path:
    """Rows with possibly different keys: the header is their union in order of appearance."""
    rows = list(rows)
    keys: list[str] = []
    seen: set[str] = set()
    for r in rows:
        for k in r:
            if k not in seen:
                seen.add(k)
                keys.append(k)
    path = Path(path)
    # Rows are sparse (a single-action run fills one action's columns of seven): filling a
    # blank line from each row's own keys, rather than asking every row for every column as
    # csv.DictWriter does, writes the same bytes at a fraction of the cost on full-size runs.
    column = {k: i for i, k in enumerate(keys)}
    blank = [""] * len(keys)
    with open_atomically(path, ConfigError, newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for r in rows:
            line = blank.copy()
            for k, v in r.items():
                line[column[k]] = v
            w.writerow(line)
    return path


def read_csv(path: str | Path) -> list[dict[str, str]]:
    with Path(path).open(newline="") as fh:
        return list(csv.DictReader(fh))


def curves_rows(label: Mapping[str, Any], curves: Curves) -> list[dict[str, Any]]:
    """One row per x: the label's fields, then mean, sd and number of runs."""
    mean, sd, n = curves.mean(), curves.sd(), curves.count()
    return [
        {
            **label,
            "x": int(x) if float(x).is_integer() else x,
            "mean": float(m),
            "sd": float(s),
            "runs": int(c),
        }
        for x, m, s, c in zip(curves.x.tolist(), mean, sd, n)
    ]
