"""Hyper-parameters by name: the layout of theta (log signal variance, log length-scales,
weight logits, λ per source) and starting rows from named natural-scale values."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = ["HYPER_KEYS", "hyperparameter_names", "start_rows"]

HYPER_KEYS = ("signal_variance", "length_scales", "modality_weights", "transfer_lambda")


def _positive(value: Any, what: str) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0):
        raise InvalidInputError(f"{what} must be a finite number > 0, got {value!r}")
    return v


def _per_modality(values: Any, names: list[str], what: str, partial: bool = False) -> list[float]:
    """Values by modality name (a mapping), or a sequence in modality order, or one scalar.
    ``partial``: a mapping may leave modalities out (NaN for them)."""
    if isinstance(values, Mapping):
        missing = [n for n in names if n not in values]
        extra = [k for k in values if k not in names]
        if (missing and not partial) or extra:
            raise InvalidInputError(f"{what} must name the modalities {names}, got {list(values)}")
        return [float(values[n]) if n in values else float("nan") for n in names]
    arr = np.atleast_1d(np.asarray(values, dtype=np.float64))
    if arr.size == 1:
        arr = np.repeat(arr, len(names))
    if arr.size != len(names):
        raise InvalidInputError(f"{what} has {arr.size} values for {len(names)} modalities")
    return arr.tolist()


def start_rows(
    starts: Mapping[Any, Mapping[str, Any]],
    classes: np.ndarray,
    spec: dict[str, Any],
    transfer: bool,
    n_lambdas: int,
    lambda_free: bool,
) -> list[list[float] | None]:
    """Per-classifier starting theta rows (NaN: the constructor's value) from named values."""
    names = spec["modality_names"]
    m = len(names)
    unknown = [label for label in starts if not np.any(classes == label)]
    if unknown:
        raise InvalidInputError(
            f"hyperparameters: class(es) {unknown!r} do not occur in y "
            f"(classes: {classes.tolist()})"
        )
    positives = [1] if classes.size == 2 and not transfer else range(classes.size)
    rows: list[list[float] | None] = []
    for k in positives:
        given = starts.get(classes[k])
        if given is None and classes.size == 2 and not transfer:
            given = starts.get(classes[0])  # the single classifier serves both classes
        if given is None:
            rows.append(None)
            continue
        bad = set(given) - set(HYPER_KEYS)
        if bad:
            raise InvalidInputError(
                f"hyperparameters[{classes[k]!r}]: unknown key(s) {sorted(bad)}; "
                f"choose from {list(HYPER_KEYS)}"
            )
        row = [np.nan] * (1 + m + (m if m > 1 else 0) + n_lambdas)
        what = f"hyperparameters[{classes[k]!r}]"
        if "signal_variance" in given:
            row[0] = float(np.log(_positive(given["signal_variance"], f"{what}.signal_variance")))
        if "length_scales" in given:
            ls = _per_modality(given["length_scales"], names, f"{what}.length_scales", partial=True)
            row[1 : 1 + m] = [
                float("nan")
                if np.isnan(v)
                else float(np.log(_positive(v, f"{what}.length_scales")))
                for v in ls
            ]
        if "modality_weights" in given and m > 1:
            w = np.asarray(
                _per_modality(given["modality_weights"], names, f"{what}.modality_weights"),
                dtype=np.float64,
            )
            if not (np.all(np.isfinite(w)) and np.all(w >= 0) and w.sum() > 0):
                raise InvalidInputError(f"{what}.modality_weights must be >= 0 with a positive sum")
            with np.errstate(divide="ignore"):
                row[1 + m : 1 + 2 * m] = np.maximum(np.log(w / w.sum()), -50.0).tolist()
        if "transfer_lambda" in given and lambda_free and n_lambdas:
            lam = given["transfer_lambda"]
            values = list(lam.values()) if isinstance(lam, Mapping) else np.ravel(lam).tolist()
            for i, v in enumerate(values[:n_lambdas]):
                row[len(row) - n_lambdas + i] = float(v)
        rows.append(row)
    return rows


def hyperparameter_names(modality_names: list[str], n_lambdas: int) -> list[str]:
    """The names of theta's entries (``LaplaceGPC.hyperparameter_names_``)."""
    names = ["log_signal_variance"] + [f"log_length_scale[{m}]" for m in modality_names]
    if len(modality_names) > 1:
        names += [f"weight_logit[{m}]" for m in modality_names]
    if n_lambdas == 1:
        names.append("transfer_lambda")
    else:
        names += [f"transfer_lambda[{s}]" for s in range(n_lambdas)]
    return names
