"""Checking the data users fit and predict on (arrays and labels) by scikit-learn's rules, with
fast paths for the plain arrays the learning loop passes at every refit. The plain arguments
(modalities, seeds, thread counts, settings) are checked in :mod:`aptkt.gp.arguments`."""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError as _SklearnNotFitted
from sklearn.utils.multiclass import check_classification_targets as _sklearn_targets
from sklearn.utils.validation import validate_data

from aptkt.errors import InvalidInputError, NotFittedError

__all__ = ["NotFitted", "check_classification_targets", "validate"]


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
