"""The new objects' kernel in the library's feature space (``GPSettings(kernel="library")``).

One kernel serves every one-vs-all classifier of an action, with equal modality weights and one
length-scale for every modality (in the noise-whitened space a unit is a noise level in every
modality):

* its amplitude σ² follows from how many new objects compete
  (:func:`~aptkt.learning.config.lone_observation_signal_variance`): a property of the task.
  Learned from the library, it would grow with the library — its objects, observed many times
  each, are separable, and separable data favour ever larger amplitudes — and a kernel certain
  of every observation learns little from the next one;
* its length-scale maximises, at that σ², the library's classifiers' summed Laplace evidence
  plus the new classifiers' plus a weak log-normal hyper-prior (centred on the library's data
  scale, one standard deviation a factor of 10): the evidence of every labelled observation the
  action has, as one kernel shared by all the classifiers implies. Where the library's objects
  pin the length-scale down, the few new labels hardly move it; where the library cannot tell
  (its objects far apart, any length-scale separating them), the new labels choose.

The library's part depends only on the library and σ², so it is computed once
(:class:`LibraryEvidence`: the summed evidence on a grid of length-scales, interpolated), and
every update of the new objects' model evaluates only their own few classifiers: the cost of an
update does not grow with the library.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar
from scipy.spatial.distance import pdist

from aptkt.gp import LaplaceGPC

__all__ = [
    "LENGTH_SCALE_PRIOR_SD",
    "LibraryEvidence",
    "data_scale",
    "library_evidence",
    "fit_new_objects",
]

#: One standard deviation of the log length-scale's hyper-prior: a factor of 10, the width of
#: every weak hyper-prior of the package.
LENGTH_SCALE_PRIOR_SD = math.log(10.0)
#: The library's evidence is evaluated on this many length-scales, from the data scale divided by
#: :data:`GRID_SPAN` to the data scale times it (evenly in log), and interpolated between them.
GRID_POINTS = 25
GRID_SPAN = 30.0


def data_scale(X: np.ndarray, columns: list[int]) -> float:
    """The median of the non-zero pairwise distances of ``X``'s rows in ``columns`` (1 without
    two distinct rows)."""
    d = pdist(np.asarray(X, dtype=np.float64)[:, columns])
    d = d[d > 0]
    if d.size == 0:
        return 1.0
    return float(np.partition(d, d.size // 2)[d.size // 2])


def _model(
    groups: Mapping[str, list[int]], signal_variance: float, length_scale: float, approximation: str
) -> LaplaceGPC:
    return LaplaceGPC(
        length_scale=float(length_scale),
        signal_variance=float(signal_variance),
        modalities=dict(groups),
        optimize=False,
        approximation=approximation,
    )


@dataclass(frozen=True)
class LibraryEvidence:
    """The library's summed Laplace log marginal likelihood (every old object's one-vs-all
    classifier) at a fixed σ², as a function of the shared length-scale: ``values`` at
    ``log_grid`` (natural logs of length-scales), interpolated by a cubic spline; ``centre``:
    the library's data scale, where the hyper-prior is centred."""

    signal_variance: float
    log_grid: np.ndarray
    values: np.ndarray
    centre: float

    def __call__(self, log_length_scale: float) -> float:
        return float(CubicSpline(self.log_grid, self.values)(log_length_scale))

    def log_prior(self, log_length_scale: float) -> float:
        z = (log_length_scale - math.log(self.centre)) / LENGTH_SCALE_PRIOR_SD
        return -0.5 * z * z

    def best(self) -> float:
        """The length-scale the library alone favours (with the hyper-prior)."""
        return math.exp(_maximise(lambda t: self(t) + self.log_prior(t), self.log_grid))


def library_evidence(
    X: np.ndarray,
    objects: np.ndarray,
    groups: Mapping[str, list[int]],
    signal_variance: float,
    *,
    approximation: str = "erf",
) -> LibraryEvidence:
    """:class:`LibraryEvidence` of the library's observations ``X`` (their objects, the model
    input's columns ``groups``) at ``signal_variance``."""
    centre = math.exp(
        float(np.mean([math.log(data_scale(X, list(cols))) for cols in groups.values()]))
    )
    log_grid = math.log(centre) + np.linspace(
        -math.log(GRID_SPAN), math.log(GRID_SPAN), GRID_POINTS
    )
    labels = np.asarray(objects)
    values = np.array(
        [
            float(
                _model(groups, signal_variance, math.exp(t), approximation)
                .fit(X, labels)
                .log_marginal_likelihood_.sum()
            )
            for t in log_grid
        ]
    )
    return LibraryEvidence(float(signal_variance), log_grid, values, centre)


def _maximise(objective, log_grid: np.ndarray) -> float:
    """The maximiser of a smooth objective of log ℓ over the grid's range: the best grid point,
    then Brent's method in the interval around it."""
    values = [objective(t) for t in log_grid]
    k = int(np.argmax(values))
    lo, hi = log_grid[max(k - 1, 0)], log_grid[min(k + 1, log_grid.size - 1)]
    if hi <= lo:
        return float(log_grid[k])
    found = minimize_scalar(
        lambda t: -objective(t), bounds=(lo, hi), method="bounded", options={"xatol": 1e-3}
    )
    return float(found.x) if -found.fun >= values[k] else float(log_grid[k])


def fit_new_objects(
    X: np.ndarray,
    objects: np.ndarray,
    groups: Mapping[str, list[int]],
    library: LibraryEvidence,
    *,
    sources: Mapping[Any, list[Any]] | None = None,
    approximation: str = "erf",
) -> LaplaceGPC:
    """The new objects' model on ``X`` (with ``sources`` per class, as :meth:`LaplaceGPC.fit`
    takes them) at the library's σ² and the length-scale maximising the library's evidence plus
    the new classifiers' plus the hyper-prior."""

    def new(t: float) -> LaplaceGPC:
        return _model(groups, library.signal_variance, math.exp(t), approximation).fit(
            X, objects, sources=sources or None
        )

    def objective(t: float) -> float:
        return library(t) + float(new(t).log_marginal_likelihood_.sum()) + library.log_prior(t)

    return new(_maximise(objective, library.log_grid))
