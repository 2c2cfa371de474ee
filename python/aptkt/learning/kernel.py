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
from functools import cached_property
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
GRID_POINTS = 17
GRID_SPAN = 30.0
#: A search that starts from an earlier optimum scans this many grid points on either side of it
#: first (and the whole grid if the best of them lies at the edge of that window).
WINDOW = 2


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

    @cached_property
    def _spline(self) -> CubicSpline:
        return CubicSpline(self.log_grid, self.values)

    def __call__(self, log_length_scale: float) -> float:
        return float(self._spline(log_length_scale))

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


def _maximise(objective, log_grid: np.ndarray, start: float | None = None) -> float:
    """The maximiser of a smooth objective of log ℓ over the grid's range: the best grid point
    (near ``start`` first, the whole grid if that best lies at the window's edge), then
    Brent's method in the interval around it."""
    values: dict[int, float] = {}

    def at(k: int) -> float:
        if k not in values:
            values[k] = objective(log_grid[k])
        return values[k]

    last = log_grid.size - 1
    if start is None:
        window = range(log_grid.size)
    else:
        near = int(np.argmin(np.abs(log_grid - start)))
        window = range(max(near - WINDOW, 0), min(near + WINDOW, last) + 1)
    k = max(window, key=at)
    if start is not None and k in (window.start, window.stop - 1) and k not in (0, last):
        k = max(range(log_grid.size), key=at)
    lo, hi = log_grid[max(k - 1, 0)], log_grid[min(k + 1, last)]
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
    start: float | None = None,
) -> LaplaceGPC:
    """The new objects' model on ``X`` (with ``sources`` per class, as :meth:`LaplaceGPC.fit`
    takes them) at the library's σ² and the length-scale maximising the library's evidence plus
    the new classifiers' plus the hyper-prior; ``start``: an earlier optimum's length-scale
    (its log), where the search begins. The chosen log length-scale is ``model.theta_[0, 1]``."""

    def fitted(t: float) -> LaplaceGPC:
        return _model(groups, library.signal_variance, math.exp(t), approximation).fit(
            X, objects, sources=sources or None
        )

    first = fitted(library.log_grid[library.log_grid.size // 2] if start is None else start)
    theta = first.theta_.copy()
    searched = list(range(1, 1 + len(groups)))

    def objective(t: float) -> float:
        # One model evaluated at other length-scales: the core's Laplace evidence per
        # classifier, each row its own λ.
        theta[:, searched] = t
        evidence = np.asarray(first.log_marginal_likelihood(theta)).sum()
        return library(t) + float(evidence) + library.log_prior(t)

    best = _maximise(objective, library.log_grid, start)
    return fitted(best)
