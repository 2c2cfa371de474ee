"""Checking and normalising what users pass: arrays, labels, modalities, seeds and thread
counts — by scikit-learn's rules, with fast paths for the plain arrays the learning loop passes
at every refit."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError as _SklearnNotFitted
from sklearn.utils.multiclass import check_classification_targets as _sklearn_targets
from sklearn.utils.validation import validate_data

from aptkt.errors import InvalidInputError, InvalidTypeError, NotFittedError

__all__ = [
    "NotFitted",
    "as_matrix",
    "check_classification_targets",
    "count",
    "normalise_modalities",
    "real",
    "seed_of",
    "threads",
    "validate",
]


def as_matrix(X: Any, name: str, n_features: int | None = None) -> np.ndarray:
    arr = np.asarray(X)
    if arr.dtype.kind not in "biuf":
        raise InvalidTypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if arr.ndim != 2:
        raise InvalidInputError(
            f"{name} must be a 2-D array (n_samples, n_features), got shape {arr.shape}"
        )
    if arr.shape[0] == 0:
        raise InvalidInputError(f"{name} has no rows")
    if n_features is not None and arr.shape[1] != n_features:
        raise InvalidInputError(f"{name} has {arr.shape[1]} features, expected {n_features}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def normalise_modalities(
    modalities: Any, n_features: int, feature_names: Any = None
) -> tuple[list[str], list[list[int]]]:
    """Modality names and their column indices. A modality's columns are indices, a slice, or
    (with ``feature_names``, the columns of the DataFrame the model is fitted to) column names."""
    if modalities is None:
        return ["all"], [list(range(n_features))]
    if isinstance(modalities, Mapping):
        items = list(modalities.items())
    else:
        items = [(f"m{i}", cols) for i, cols in enumerate(modalities)]
    if not items:
        raise InvalidInputError("modalities must name at least one group of feature columns")
    names, groups = [], []
    for name, cols in items:
        if isinstance(cols, slice):
            cols = range(n_features)[cols]
        elif isinstance(cols, str):
            cols = [cols]
        listed = list(np.atleast_1d(np.asarray(cols, dtype=object)))
        if listed and all(isinstance(c, str) for c in listed):
            idx = _by_name(str(name), [str(c) for c in listed], feature_names)
        elif any(isinstance(c, str) for c in listed):
            raise InvalidTypeError(
                f"modality {name!r} mixes column names and indices: {listed}; give one kind"
            )
        else:
            idx = [int(c) for c in np.atleast_1d(np.asarray(cols, dtype=np.int64))]
        bad = [c for c in idx if not 0 <= c < n_features]
        if not idx or bad:
            raise InvalidInputError(
                f"modality {name!r} must list feature columns in [0, {n_features}), got {list(cols)}"
            )
        names.append(str(name))
        groups.append(idx)
    return names, groups


def _by_name(modality: str, columns: list[str], feature_names: Any) -> list[int]:
    if feature_names is None:
        raise InvalidTypeError(
            f"modality {modality!r} names columns {columns}, but X has no column names: fit "
            "to a DataFrame with these columns, or give column indices"
        )
    position = {str(n): i for i, n in enumerate(feature_names)}
    unknown = [c for c in columns if c not in position]
    if unknown:
        raise InvalidInputError(
            f"modality {modality!r}: X has no column(s) {unknown}; its columns are {list(position)}"
        )
    return [position[c] for c in columns]


class NotFitted(NotFittedError, _SklearnNotFitted):
    """Both the project's and scikit-learn's "not fitted" error, so either can be caught."""


def check_classification_targets(y: np.ndarray) -> None:
    """scikit-learn's ``check_classification_targets`` without its cost in the common case: a
    1-D array of integers, booleans or strings is always "binary" or "multiclass", which it
    accepts. (It costs ~0.8 ms, a fifth of a small fit in the learning loop, which refits
    after every observation.) Anything else (floats, objects, 2-D) goes through it."""
    if y.ndim == 1 and y.dtype.kind in "biuU":
        return
    _sklearn_targets(y)


#: ``validate``'s "no target given" (``y=None`` is a user's mistake that scikit-learn reports).
_NO_TARGET: Any = object()


def validate(estimator: BaseEstimator, X: Any, y: Any = _NO_TARGET, *, reset: bool) -> Any:
    """scikit-learn's ``validate_data`` (float64, non-finite values allowed), without its cost
    in the common case: a non-empty 2-D float64 ndarray, and for ``fit`` a 1-D array of
    integers, booleans or strings of the same length. For those its checks reduce to the
    number of features, and there are no feature names to record or compare; it costs
    ~0.3 ms a call (dataframe detection), a sixth of a small run of the learning loop, which
    validates at every refit and prediction. Anything else, and any estimator fitted with
    feature names, goes through it."""
    plain = (
        type(X) is np.ndarray
        and X.dtype == np.float64
        and X.ndim == 2
        and X.shape[0] > 0
        and X.shape[1] > 0
        and not hasattr(estimator, "feature_names_in_")
    )
    if y is not _NO_TARGET:
        plain = plain and (
            type(y) is np.ndarray
            and y.ndim == 1
            and y.dtype.kind in "biuU"
            and y.shape[0] == X.shape[0]
        )
    if not plain:
        if y is _NO_TARGET:
            return validate_data(
                estimator, X, reset=reset, dtype=np.float64, ensure_all_finite=False
            )
        return validate_data(estimator, X, y, dtype=np.float64, ensure_all_finite=False)
    if reset:
        estimator.n_features_in_ = X.shape[1]
    elif X.shape[1] != estimator.n_features_in_:
        raise InvalidInputError(
            f"X has {X.shape[1]} features, but {type(estimator).__name__} is expecting "
            f"{estimator.n_features_in_} features as input."
        )
    return X if y is _NO_TARGET else (X, y)


def threads(n_jobs: Any) -> int:
    """Threads for ``n_jobs`` by joblib's convention: None -> 1, -1 -> every core, -2 -> all
    but one, and so on; never more than the machine's cores (more threads only share them, and
    each one costs memory: a huge ``n_jobs`` once started threads without end)."""
    if n_jobs is None:
        return 1
    if isinstance(n_jobs, bool) or not isinstance(n_jobs, (int, np.integer)) or n_jobs == 0:
        raise InvalidInputError(f"n_jobs must be None or a non-zero integer, got {n_jobs!r}")
    cores = os.cpu_count() or 1
    if n_jobs > 0:
        return min(int(n_jobs), cores)
    return max(1, cores + 1 + int(n_jobs))


def real(value: Any, name: str, *, positive: bool = False) -> float:
    """A setting that must be a finite real number (not a bool), > 0 or >= 0."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not np.isfinite(value)
        or not (value > 0 if positive else value >= 0)
    ):
        raise InvalidInputError(
            f"{name} must be a finite number {'>' if positive else '>='} 0, got {value!r}"
        )
    return float(value)


def count(value: Any, name: str, maximum: int) -> int:
    """A setting that must be an integer (not a bool) in ``0..maximum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise InvalidInputError(f"{name} must be a non-negative integer, got {value!r}")
    if value > maximum:
        raise InvalidInputError(f"{name} must be at most {maximum}, got {value}")
    return int(value)


def seed_of(random_state: Any) -> int:
    if random_state is None:
        return int(np.random.SeedSequence().generate_state(1, np.uint64)[0])
    if isinstance(random_state, (int, np.integer)):
        if random_state < 0:
            raise InvalidInputError(f"random_state must be >= 0, got {random_state}")
        return int(random_state) & 0xFFFF_FFFF_FFFF_FFFF
    if isinstance(random_state, np.random.Generator):
        return int(random_state.integers(0, 2**63))
    if isinstance(random_state, np.random.RandomState):
        return int(random_state.randint(0, 2**31 - 1))
    raise InvalidTypeError(
        f"random_state must be None, an int or a numpy Generator, got {type(random_state).__name__}"
    )
