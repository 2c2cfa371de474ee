"""The kernel matrix at given hyper-parameters, for inspection and tests."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aptkt import _core
from aptkt.errors import InvalidInputError
from aptkt.gp.arguments import as_matrix, normalise_modalities

__all__ = ["kernel_matrix"]


def kernel_matrix(
    X: Any,
    theta: Any,
    *,
    modalities: Mapping[str, Sequence[int]] | Sequence[Sequence[int]] | None = None,
    n_source: int | Sequence[int] = 0,
) -> np.ndarray:
    """The kernel matrix of ``X`` at ``theta`` (layout as ``LaplaceGPC.theta_``).

    ``n_source``: the first rows of ``X`` that belong to source tasks, as one count (a single
    source task) or a sequence of counts (several source tasks in order); the remaining rows
    are the target task. Theta then ends with one λ ∈ [-1, 1] per source task.
    """
    X = as_matrix(X, "X")
    _, groups = normalise_modalities(modalities, X.shape[1])
    if isinstance(n_source, (int, np.integer)):
        sizes = [int(n_source)] if int(n_source) > 0 else []
    else:
        sizes = [int(v) for v in n_source]
    if any(v < 0 for v in sizes):
        raise InvalidInputError(f"n_source must hold counts >= 0, got {n_source!r}")
    return np.asarray(_core.kernel_matrix(X, [float(v) for v in np.ravel(theta)], groups, sizes))
