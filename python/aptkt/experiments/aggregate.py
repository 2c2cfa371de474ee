"""From per-step result rows to learning curves, their spread, and paired comparisons.

A *run* is identified by some of its tags (``group`` and ``trial`` by default); a
:class:`Curves` holds one row of values per run and one column per x (the step, or the number
of observations), NaN where a run has no such step (a run that stopped early). Methods
compared on the same runs (same group, same trial seed: same pool order and exploration
draws) are compared run by run (:func:`difference`).

Spread: the standard deviation over runs (``ddof=0``), as the report's tables give it.
The plots' bands are 95 % Student-t intervals of the mean over runs (:func:`mean_band`).
Uncertainty of a mean: a 95 % Student-t interval over independent units — the prior-object
groups when there are several (runs of one group share its prior objects, so they are not
independent), otherwise the runs.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError, UnknownNameError

__all__ = [
    "Curves",
    "Estimate",
    "collect",
    "difference",
    "mean_over_panels",
    "estimate",
    "t_quantile",
    "mean_band",
]

# Two-sided 95 % quantiles of Student's t (df -> t_0.975); between table entries the quantile
# is interpolated linearly in 1/df, which is exact to 3 decimals here.
_T975 = {
    1: 12.706,
    2: 4.303,
    3: 3.182,
    4: 2.776,
    5: 2.571,
    6: 2.447,
    7: 2.365,
    8: 2.306,
    9: 2.262,
    10: 2.228,
    11: 2.201,
    12: 2.179,
    13: 2.160,
    14: 2.145,
    15: 2.131,
    16: 2.120,
    17: 2.110,
    18: 2.101,
    19: 2.093,
    20: 2.086,
    25: 2.060,
    30: 2.042,
    40: 2.021,
    60: 2.000,
    120: 1.980,
}


def t_quantile(df: int) -> float:
    """The 97.5 % quantile of Student's t with ``df`` degrees of freedom."""
    if df < 1:
        raise InvalidInputError(f"degrees of freedom must be >= 1, got {df}")
    if df in _T975:
        return _T975[df]
    keys = sorted(_T975)
    if df > keys[-1]:
        lo, hi, t_lo, t_hi = keys[-1], math.inf, _T975[keys[-1]], 1.959964
    else:
        hi = min(k for k in keys if k > df)
        lo = max(k for k in keys if k < df)
        t_lo, t_hi = _T975[lo], _T975[hi]
    w = (1 / lo - 1 / df) / (1 / lo - (0 if math.isinf(hi) else 1 / hi))
    return t_lo + w * (t_hi - t_lo)


def mean_band(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column of ``values`` (runs × x): the mean over runs and its 95 % Student-t interval
    ``mean ± t(n-1) · sd / √n`` (``sd`` with ``ddof=1``, ``n`` the finite runs of the column).
    Where fewer than two runs have a value the interval is NaN (no band can be drawn)."""
    v = np.asarray(values, dtype=float)
    if v.ndim != 2:
        raise InvalidInputError(f"values must be (runs, x), got shape {v.shape}")
    n = np.sum(np.isfinite(v), axis=0)
    mean = _quiet(np.nanmean, v, axis=0)
    half = np.full(v.shape[1], np.nan)
    ok = n >= 2
    if np.any(ok):
        sd = _quiet(np.nanstd, v[:, ok], axis=0, ddof=1)
        t = np.array([t_quantile(int(k) - 1) for k in n[ok]])
        half[ok] = t * sd / np.sqrt(n[ok])
    return mean, mean - half, mean + half


def _quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns give NaN, silently
        return fn(*args, **kw)


@dataclass
class Curves:
    """Values of several runs over a common x axis: ``values[run, i]`` at ``x[i]``."""

    x: np.ndarray
    values: np.ndarray
    runs: list[tuple]

    def __post_init__(self) -> None:
        self.x = np.asarray(self.x)
        self.values = np.asarray(self.values, dtype=float)
        if self.values.shape != (len(self.runs), len(self.x)):
            raise InvalidInputError(
                f"values have shape {self.values.shape}, expected ({len(self.runs)}, {len(self.x)})"
            )
        if len(set(self.runs)) != len(self.runs):
            raise InvalidInputError("a run occurs twice")

    @property
    def n_runs(self) -> int:
        return len(self.runs)

    def mean(self) -> np.ndarray:
        return _quiet(np.nanmean, self.values, axis=0)

    def sd(self) -> np.ndarray:
        return _quiet(np.nanstd, self.values, axis=0)

    def count(self) -> np.ndarray:
        return np.sum(np.isfinite(self.values), axis=0)

    def column(self, x_value: Any) -> np.ndarray:
        where = np.flatnonzero(self.x == x_value)
        if where.size != 1:
            raise UnknownNameError(f"x = {x_value!r} is not on this curve's axis {self.x.tolist()}")
        return self.values[:, int(where[0])]

    def run_means(self) -> np.ndarray:
        """Each run's mean over x (an area-under-the-curve summary)."""
        return _quiet(np.nanmean, self.values, axis=1)

    def by_unit(self, level: int = 0) -> dict[Any, np.ndarray]:
        """Rows grouped by one element of the run identity (e.g. the group)."""
        out: dict[Any, list[int]] = {}
        for i, r in enumerate(self.runs):
            out.setdefault(r[level], []).append(i)
        return {u: self.values[idx] for u, idx in out.items()}

    def units(self, level: int = 0) -> list[Any]:
        return [r[level] for r in self.runs]


def _matches(row: Mapping[str, Any], where: Mapping[str, Any]) -> bool:
    for k, v in where.items():
        if k not in row:
            return False
        if isinstance(v, (list, tuple, set, frozenset)):
            if row[k] not in v:
                return False
        elif row[k] != v:
            return False
    return True


def collect(
    rows: Iterable[Mapping[str, Any]],
    where: Mapping[str, Any] | None = None,
    *,
    run_by: Sequence[str] = ("group", "run"),
    x: str = "step",
    value: str = "mean_accuracy",
) -> Curves:
    """The curves of the rows matching ``where`` (tag -> value, or -> collection of values).

    Raises if no row matches or if a run has two rows at the same x (two runs mixed up under
    one identity — a bookkeeping error, never averaged away).
    """
    where = dict(where or {})
    cells: dict[tuple, dict[Any, float]] = {}
    xs: set[Any] = set()
    for row in rows:
        if not _matches(row, where):
            continue
        missing = [k for k in (*run_by, x) if k not in row]
        if missing:
            raise UnknownNameError(f"a result row has no {missing} (row: {dict(row)})")
        run = tuple(row[k] for k in run_by)
        per = cells.setdefault(run, {})
        if row[x] in per:
            raise InvalidInputError(
                f"run {dict(zip(run_by, run))} has two rows at {x} = {row[x]} (filter {where})"
            )
        v = row.get(value)
        per[row[x]] = float("nan") if v is None or v == "" else float(v)
        xs.add(row[x])
    if not cells:
        raise UnknownNameError(f"no result rows match {where}")
    axis = sorted(xs)
    pos = {v: i for i, v in enumerate(axis)}
    runs = sorted(cells)
    values = np.full((len(runs), len(axis)), np.nan)
    for r, run in enumerate(runs):
        for xv, v in cells[run].items():
            values[r, pos[xv]] = v
    return Curves(np.asarray(axis), values, runs)


def difference(a: Curves, b: Curves) -> Curves:
    """Run-by-run ``a - b`` on the runs both have (paired comparison)."""
    if a.x.shape != b.x.shape or not np.array_equal(a.x, b.x):
        raise InvalidInputError(f"different x axes: {a.x.tolist()} vs {b.x.tolist()}")
    common = [r for r in a.runs if r in set(b.runs)]
    if not common:
        raise InvalidInputError("the two curves share no run")
    ia = {r: i for i, r in enumerate(a.runs)}
    ib = {r: i for i, r in enumerate(b.runs)}
    values = np.array([a.values[ia[r]] - b.values[ib[r]] for r in common])
    return Curves(a.x, values, common)


def mean_over_panels(panels: Sequence[Curves]) -> Curves:
    """Per run, the mean of several panels' curves (e.g. over actions); panels must have the
    same runs and x axis."""
    if not panels:
        raise InvalidInputError("no panels to average")
    first = panels[0]
    for p in panels[1:]:
        if p.runs != first.runs or not np.array_equal(p.x, first.x):
            raise InvalidInputError("panels to average must have the same runs and x axis")
    return Curves(
        first.x, _quiet(np.nanmean, np.stack([p.values for p in panels]), axis=0), list(first.runs)
    )


@dataclass(frozen=True)
class Estimate:
    """A mean with its 95 % t interval over ``n`` independent ``unit``\\ s."""

    mean: float
    low: float
    high: float
    n: int
    unit: str

    @property
    def significant_positive(self) -> bool:
        return self.low > 0

    @property
    def significant_negative(self) -> bool:
        return self.high < 0

    @property
    def why_no_interval(self) -> str | None:
        """Why there is no interval (too few units), or None when there is one."""
        if math.isfinite(self.low) and math.isfinite(self.high):
            return None
        if self.n == 0:
            return f"no {self.unit}"
        one = self.unit.removesuffix("s") if self.n == 1 else self.unit
        return f"{self.n} {one}: a 95 % interval needs at least 2"

    def as_dict(self) -> dict[str, Any]:
        """The estimate for a JSON file; without an interval, ``low`` and ``high`` are null
        and ``no_interval`` says why."""
        out: dict[str, Any] = {
            "mean": self.mean,
            "low": self.low,
            "high": self.high,
            "n": self.n,
            "unit": self.unit,
        }
        why = self.why_no_interval
        if why is not None:
            out["no_interval"] = why
        return out


def estimate(
    values: Sequence[float] | np.ndarray,
    units: Sequence[Any] | None = None,
    *,
    unit_name: str = "group",
) -> Estimate:
    """Mean of ``values`` with a 95 % t interval. With ``units`` (one per value) and at least
    two distinct units, values are first averaged within each unit and the interval is over
    units; otherwise over the values ("runs")."""
    v = np.asarray(values, dtype=float)
    keep = np.isfinite(v)
    if units is not None:
        u = list(units)
        if len(u) != v.size:
            raise InvalidInputError("one unit per value is needed")
        u = [x for x, k in zip(u, keep) if k]
    v = v[keep]
    if v.size == 0:
        return Estimate(float("nan"), float("nan"), float("nan"), 0, "runs")
    # One value of one unit is that unit's ("1 order: no interval", not "1 run").
    name = unit_name + "s" if units is not None and v.size == 1 else "runs"
    if units is not None and len(set(u)) >= 2:
        order = list(dict.fromkeys(u))
        v = np.array([v[[i for i, x in enumerate(u) if x == g]].mean() for g in order])
        name = unit_name + "s"
    m = float(v.mean())
    if v.size < 2:
        return Estimate(m, float("nan"), float("nan"), int(v.size), name)
    half = t_quantile(v.size - 1) * float(v.std(ddof=1)) / math.sqrt(v.size)
    return Estimate(m, m - half, m + half, int(v.size), name)
