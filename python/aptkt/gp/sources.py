"""Transfer sources: a prior object's observations (and labels) coupled into one class's
binary classifier by the dependent kernel, with their relatedness λ."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError, InvalidTypeError
from aptkt.gp.arguments import as_matrix

__all__ = ["TransferSource", "normalise_sources", "start_lambda"]


class TransferSource:
    """A source task (a prior object) transferred into one class's binary classifier.

    Parameters
    ----------
    X : array (n_source, n_features)
        The source task's observations, in the target's feature space.
    y : None or array (n_source,)
        Their labels for this binary task. None: positives only (every row +1, the old object's
        own observations). Otherwise the source object's one-vs-all task: +1 for its own
        observations, -1 for the other old objects' (values in {+1, -1}, or booleans / {0, 1}
        with 1 = positive).
    transfer_lambda : float in [0, 1], optional
        Relatedness λ_s of this source to the target task: the kernel between its rows and the
        new observations is scaled by λ_s. Required when λ is fixed (the default); a starting
        value (0.5 if None) when λ is learned.
    name : str, optional
        Names this source in ``hyperparameters_`` (default ``source<k>``).
    """

    __slots__ = ("X", "name", "transfer_lambda", "y")

    def __init__(
        self,
        X: Any,
        y: Any = None,
        transfer_lambda: float | None = None,
        *,
        name: str | None = None,
    ) -> None:
        if y is not None and np.ndim(y) == 0:
            raise InvalidTypeError(
                "TransferSource(X, y, transfer_lambda): y must be an array of labels or None, "
                f"got the scalar {y!r}; pass the relatedness as transfer_lambda=..."
            )
        X = as_matrix(X, "TransferSource.X")
        self.X = X
        self.y = None if y is None else _binary_labels(y, X.shape[0])
        if transfer_lambda is not None:
            lam = float(transfer_lambda)
            if not 0.0 <= lam <= 1.0:  # also rejects NaN
                raise InvalidInputError(
                    f"transfer_lambda must lie in [0, 1], got {transfer_lambda!r}"
                )
            transfer_lambda = lam
        self.transfer_lambda = transfer_lambda
        self.name = None if name is None else str(name)

    @property
    def labels(self) -> np.ndarray:
        """The ±1 labels this source enters its binary classifier with."""
        return np.ones(self.X.shape[0]) if self.y is None else self.y

    def __repr__(self) -> str:
        kind = "positives" if self.y is None else f"{int((self.y > 0).sum())} positives"
        return (
            f"TransferSource({self.X.shape[0]} rows, {kind}, "
            f"transfer_lambda={self.transfer_lambda!r}, name={self.name!r})"
        )


def _binary_labels(y: Any, n: int) -> np.ndarray:
    """±1 float labels from {+1, -1}, {1, 0} or booleans, checked for length and finiteness."""
    arr = np.asarray(y)
    if arr.ndim != 1 or arr.shape[0] != n:
        raise InvalidInputError(
            f"TransferSource.y must have one label per row of X ({n}), got shape {arr.shape}"
        )
    if arr.dtype.kind == "b":
        return np.where(arr, 1.0, -1.0)
    if arr.dtype.kind not in "iuf":
        raise InvalidTypeError(
            f"TransferSource.y must hold numbers or booleans, got dtype {arr.dtype}"
        )
    values = arr.astype(np.float64)
    if not np.all(np.isfinite(values)):
        raise InvalidInputError("TransferSource.y contains a non-finite value")
    positive = values == 1.0
    if np.all(positive | (values == -1.0)):
        return values
    if np.all(positive | (values == 0.0)):
        return np.where(positive, 1.0, -1.0)
    raise InvalidInputError(
        "TransferSource.y must be binary (+1/-1, 1/0 or booleans), got values "
        f"{sorted(set(np.unique(values).tolist()))}"
    )


def _as_source(value: Any, where: str) -> TransferSource:
    if isinstance(value, TransferSource):
        return value
    if isinstance(value, tuple) and len(value) == 2 and np.ndim(value[1]) == 0:
        return TransferSource(value[0], transfer_lambda=value[1])
    raise InvalidTypeError(
        f"{where} must be a TransferSource, an (X, transfer_lambda) tuple or a list of those, "
        f"got {type(value).__name__}"
    )


def normalise_sources(
    sources: Mapping[Any, Any] | None, classes: np.ndarray, n_features: int, lambda_free: bool
) -> dict[Any, list[TransferSource]]:
    """Class label -> list of checked sources with names (``source<k>`` by default)."""
    used: dict[Any, list[TransferSource]] = {}
    for label, value in (sources or {}).items():
        where = f"sources[{label!r}]"
        if np.flatnonzero(classes == label).size != 1:
            raise InvalidInputError(
                f"sources: class {label!r} does not occur in y (classes: {classes.tolist()})"
            )
        items = value if isinstance(value, list) else [value]
        if not items:
            continue
        out = []
        for k, item in enumerate(items):
            src = _as_source(item, where)
            if src.X.shape[1] != n_features:
                raise InvalidInputError(
                    f"{where}.X has {src.X.shape[1]} features, expected {n_features}"
                )
            if src.transfer_lambda is None and not lambda_free:
                raise InvalidInputError(
                    f"{where}: transfer_lambda is required while λ is fixed "
                    "(fixed includes 'transfer_lambda')"
                )
            name = src.name if src.name is not None else f"source{k}"
            out.append(TransferSource(src.X, src.y, src.transfer_lambda, name=name))
        names = [s.name for s in out]
        if len(set(names)) != len(names):
            raise InvalidInputError(f"{where}: source names must differ, got {names}")
        used[label] = out
    return used


def start_lambda(source: TransferSource) -> float:
    """λ's initial value: the source's, or the middle of [0, 1] when it is to be learned."""
    return 0.5 if source.transfer_lambda is None else float(source.transfer_lambda)


def kernel_task_lists(
    kernel_tasks: Any, n_features: int
) -> list[tuple[np.ndarray, np.ndarray, int, list[list[tuple[np.ndarray, np.ndarray, float]]]]]:
    """The core's form of ``LaplaceGPC.fit``'s ``kernel_tasks`` — ``(X, y)`` or ``(X, y,
    sources)`` each, checked like the model's own data: rows, class indices, the number of
    classes and each class's source tasks."""
    from aptkt.gp.inputs import check_classification_targets

    out = []
    for i, task in enumerate(kernel_tasks):
        if not isinstance(task, (tuple, list)) or len(task) not in (2, 3):
            raise InvalidInputError(
                f"kernel_tasks[{i}] must be (X, y) or (X, y, sources), got {type(task).__name__}"
            )
        X = np.ascontiguousarray(as_matrix(task[0], f"kernel_tasks[{i}] X", n_features))
        y = np.asarray(task[1])
        if y.ndim != 1 or y.shape[0] != X.shape[0]:
            raise InvalidInputError(
                f"kernel_tasks[{i}]: X has {X.shape[0]} rows but y has shape {y.shape}"
            )
        check_classification_targets(y)
        classes, labels = np.unique(y, return_inverse=True)
        if classes.size < 2:
            raise InvalidInputError(f"kernel_tasks[{i}] needs at least two classes")
        lists: list[list[tuple[np.ndarray, np.ndarray, float]]] = [[] for _ in classes]
        if len(task) == 3 and task[2]:
            for label, lst in normalise_sources(task[2], classes, n_features, False).items():
                k = int(np.flatnonzero(classes == label)[0])
                lists[k] = [(s.X, s.labels, start_lambda(s)) for s in lst]
        out.append((X, labels.astype(np.int64), int(classes.size), lists))
    return out
