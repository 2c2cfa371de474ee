"""Checking and normalising the plain arguments users pass: matrices, modalities, seeds,
thread counts and numeric settings. No scikit-learn here: the settings (and so the command
line's parsers) need these checks, and importing scikit-learn costs about a second."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError, InvalidTypeError

__all__ = ["as_matrix", "count", "normalise_modalities", "real", "seed_of", "threads"]


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
