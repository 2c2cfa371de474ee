"""Object similarity from Gaussian mixture models (paper §5.6, Fig. 10).

Per action, every object's feature observations are clustered by a Gaussian mixture with one
component per object, each component initialised at that object's observations (component k
starts at object k's mean, with a weight proportional to its observations), then refined by EM
(at most 100 iterations, stopping when the mean log-likelihood changes by less than 1e-3: the
paper's settings, which are also scikit-learn's defaults).

The covariance is *tied* (one full covariance shared by the components) by default: with the
paper's 20 observations per object and 11–22 feature dimensions, a full covariance per
component is singular (rank ≤ 19), each component collapses onto its own object's points and
every object looks dissimilar to every other. A shared covariance, estimated from all
observations, is well determined and keeps each component on its object, so the confusion
measures how much the objects' observations overlap. ``"full"`` and ``"diag"`` are available.

The confusion of object i with object k is the mean responsibility of component k for object
i's observations; the matrix shown is rescaled to 0–1 (min-max over the matrix). It is also
kept as logarithms, because most off-diagonal entries underflow to 0 in double precision and
the choice of dissimilar priors must still order them.

A prior is *dissimilar* to the new objects when its largest similarity with any of them (the
mean of both directions, ``(C[i, j] + C[j, i]) / 2``) is small: transfer picks, per new
object, the most related prior, so a prior is harmless only if no new object resembles it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = [
    "MixtureFit",
    "fit_mixture",
    "log_responsibilities",
    "log_confusion",
    "rescale",
    "dissimilar_priors",
    "COVARIANCE_TYPES",
]

_EPS = 10 * np.finfo(float).eps
COVARIANCE_TYPES = ("tied", "full", "diag")


@dataclass
class MixtureFit:
    """A fitted Gaussian mixture. ``covariances`` is (k, d, d) for every covariance type (the
    tied one repeated, the diagonal ones as diagonal matrices), for uniform use."""

    weights: np.ndarray  # (k,)
    means: np.ndarray  # (k, d)
    covariances: np.ndarray  # (k, d, d)
    covariance_type: str
    n_iter: int
    converged: bool
    lower_bound: float  # mean log-likelihood per sample at the last E-step


def _m_step(X: np.ndarray, resp: np.ndarray, reg: float, kind: str):
    n, d = X.shape
    nk = resp.sum(axis=0) + _EPS
    means = resp.T @ X / nk[:, None]
    k = len(nk)
    cov = np.empty((k, d, d))
    if kind == "tied":
        shared = X.T @ X - (nk[:, None] * means).T @ means
        shared = shared / n
        shared.flat[:: d + 1] += reg
        cov[:] = shared
    elif kind == "full":
        for j in range(k):
            diff = X - means[j]
            cov[j] = (resp[:, j, None] * diff).T @ diff / nk[j]
            cov[j].flat[:: d + 1] += reg
    else:  # diag
        var = resp.T @ (X * X) / nk[:, None] - means**2 + reg
        cov[:] = 0.0
        for j in range(k):
            cov[j].flat[:: d + 1] = np.maximum(var[j], reg)
    return nk / n, means, cov


def _log_gaussian(X: np.ndarray, means: np.ndarray, cov: np.ndarray) -> np.ndarray:
    n, d = X.shape
    out = np.empty((n, len(means)))
    for j in range(len(means)):
        L = np.linalg.cholesky(cov[j])
        z = np.linalg.solve(L, (X - means[j]).T)
        out[:, j] = -0.5 * (d * np.log(2 * np.pi) + np.sum(z * z, axis=0)) - np.sum(
            np.log(np.diag(L))
        )
    return out


def _e_step(
    X: np.ndarray, weights: np.ndarray, means: np.ndarray, cov: np.ndarray
) -> tuple[float, np.ndarray]:
    weighted = _log_gaussian(X, means, cov) + np.log(weights)
    top = weighted.max(axis=1, keepdims=True)
    norm = top[:, 0] + np.log(np.exp(weighted - top).sum(axis=1))
    return float(norm.mean()), weighted - norm[:, None]


def fit_mixture(
    X: np.ndarray,
    init_labels: Sequence[int] | np.ndarray,
    n_components: int,
    *,
    covariance_type: str = "tied",
    max_iter: int = 100,
    tol: float = 1e-3,
    reg_covar: float = 1e-6,
) -> MixtureFit:
    """EM for a Gaussian mixture whose component k starts from the samples with
    ``init_labels == k`` (every component needs at least one). ``reg_covar`` is added to the
    covariances' diagonals (as scikit-learn does)."""
    if covariance_type not in COVARIANCE_TYPES:
        raise InvalidInputError(
            f"covariance_type must be one of {COVARIANCE_TYPES}, got {covariance_type!r}"
        )
    X = np.asarray(X, dtype=float)
    labels = np.asarray(init_labels)
    if X.ndim != 2 or labels.shape != (X.shape[0],):
        raise InvalidInputError(f"expected X (n, d) and n labels, got {X.shape} and {labels.shape}")
    if not np.all(np.isfinite(X)):
        raise InvalidInputError("X holds non-finite values")
    if max_iter < 1:
        raise InvalidInputError("max_iter must be >= 1")
    if (
        labels.size == 0
        or labels.min() < 0
        or labels.max() >= n_components
        or np.any(np.bincount(labels, minlength=n_components) == 0)
    ):
        raise InvalidInputError(
            f"every component 0..{n_components - 1} needs at least one initial sample"
        )
    resp = np.zeros((X.shape[0], n_components))
    resp[np.arange(X.shape[0]), labels] = 1.0
    params = _m_step(X, resp, reg_covar, covariance_type)
    lower, converged, n_iter = -np.inf, False, 0
    for n_iter in range(1, max_iter + 1):  # noqa: B007 - reported after the loop
        previous = lower
        lower, log_resp = _e_step(X, *params)
        params = _m_step(X, np.exp(log_resp), reg_covar, covariance_type)
        if abs(lower - previous) < tol:
            converged = True
            break
    return MixtureFit(params[0], params[1], params[2], covariance_type, n_iter, converged, lower)


def log_responsibilities(fit: MixtureFit, X: np.ndarray) -> np.ndarray:
    """log p(component | x) for each row of ``X`` (n, k)."""
    return _e_step(np.asarray(X, dtype=float), fit.weights, fit.means, fit.covariances)[1]


def log_confusion(
    log_resp: np.ndarray, labels: Sequence[int] | np.ndarray, n_objects: int
) -> np.ndarray:
    """``log C[i, k]`` with ``C[i, k]`` the mean responsibility of component k for object i's
    samples (rows of C sum to 1), computed without underflow."""
    label = np.asarray(labels)
    out = np.empty((n_objects, log_resp.shape[1]))
    for i in range(n_objects):
        rows = log_resp[label == i]
        if rows.shape[0] == 0:
            raise InvalidInputError(f"object {i} has no samples")
        top = rows.max(axis=0)
        out[i] = top + np.log(np.exp(rows - top).sum(axis=0)) - np.log(rows.shape[0])
    return out


def rescale(matrix: np.ndarray) -> np.ndarray:
    """Min-max rescaling to [0, 1] (a constant matrix becomes all zeros)."""
    m = np.asarray(matrix, dtype=float)
    lo, hi = float(m.min()), float(m.max())
    return (m - lo) / (hi - lo) if hi > lo else np.zeros_like(m)


def dissimilar_priors(
    log_similarity: np.ndarray,
    objects: Sequence[str],
    priors: Sequence[str],
    new_objects: Sequence[str],
    count: int,
) -> tuple[list[str], dict[str, float]]:
    """The ``count`` priors least similar to the new objects, and every prior's score: log10 of
    its largest similarity with any new object (mean of both directions). Ties go to the
    earlier object. Rescaling the matrix to 0–1 is monotone, so it does not change the order."""
    objects = list(objects)
    if not 1 <= count <= len(priors):
        raise InvalidInputError(f"cannot pick {count} of {len(priors)} priors")
    logs = np.asarray(log_similarity, dtype=float)
    sym = np.logaddexp(logs, logs.T) - np.log(2.0)
    cols = [objects.index(o) for o in new_objects]
    score = {p: float(sym[objects.index(p), cols].max() / np.log(10)) for p in priors}
    order = sorted(priors, key=lambda p: (score[p], objects.index(p)))
    return order[:count], score
