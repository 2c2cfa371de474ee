"""Which known object is this, or none of them: a generative model of a library's objects in
its noise-whitened feature space.

The two-covariance model of probabilistic linear discriminant analysis (Ioffe, *Probabilistic
linear discriminant analysis*, ECCV 2006; Prince and Elder, ICCV 2007), as speaker
verification uses it to ask "is this the enrolled speaker, or someone else?":

* an object's observations scatter around the object's mean with the sensor's within-object
  noise W (pooled over the library, Ledoit–Wolf shrunk), scaled per object by how noisy that object is
  (``noise_levels_``: a scalar per object, its own residual variance over the pooled one,
  shrunk towards 1 by one observation's worth of the pooled noise);
* the means of objects — known or not — scatter around the library's centre with the
  between-object covariance B (the object means' covariance, with a prior worth as many objects
  as there are columns that makes it isotropic where the few means say nothing, minus the
  share of the noise each mean still carries).

For a set V of n observations of one object, the model compares "V is old object i" — V's mean
lies within the noise of i's mean, and V scatters as i does — with "V is an object not in the
library" — V's mean is a fresh draw from B. With a prior probability ``p_new`` that an object
is not in the library, and the rest shared equally among the N known objects, the posterior is
``P(i | V) ∝ (1 − p_new)/N · p(V | i)`` and ``P(new | V) ∝ p_new · p(V | new)``: a known object
must beat every other known object *and* the chance of being a new one, and the more objects
the library holds, the more evidence one of them needs (each starts with 1/N of the prior).
Unlike a discriminative classifier of the old objects, whose one-vs-all probabilities also
claim observations that are like none of them, the likelihood of "none of them" is explicit.

**At any size.** Everything the model holds is a sum over observations or over objects: per
object its count, mean and residual sum of squares; pooled, the residuals' scatter matrix and
the sum of their fourth powers (all Ledoit and Wolf's shrinkage needs), and the first two
moments of the object means. The model of the library without one observation or without one
object — what the library's calibrations ask for, once per observation or object — is the same
model of those sums minus that observation's or object's share: exact, and computed in
O(d³) plus the objects it is asked about, instead of a refit over every observation. Memory
is the observations and O(N·d + d²).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np
from scipy.special import logsumexp

from aptkt.errors import InvalidInputError, UnknownNameError

__all__ = [
    "ObjectIdentity",
    "NEW_OBJECT_PRIOR",
    "IMPOSTOR_COMPETITORS",
    "impostor_parts",
    "impostor_table",
]

#: Prior probability that an object presented to the robot is not one of the library's: as
#: likely as not — neither the library nor the lab knows better before the first touch.
NEW_OBJECT_PRIOR = 0.5
#: How many of the library's objects compete with a left-out object when the library judges how
#: alike its own distinct objects look (:meth:`ObjectIdentity.impostor_log_odds`): its nearest
#: ones in the library's metric. A farther object only adds to the mass of "someone else", so
#: leaving it out can only raise the odds — a stricter threshold, never a laxer one; with at most
#: this many other objects, every object competes and the odds are exact.
IMPOSTOR_COMPETITORS = 64


@dataclass(frozen=True)
class _Pooled:
    """The sums the model is a function of, over a set of objects (see the module docstring);
    object means enter relative to ``reference``, which keeps their second moment well
    conditioned."""

    n_objects: int
    n_rows: int
    scatter: np.ndarray  # Σ r rᵀ over every residual r = x − (its object's mean)
    quartic: float  # Σ ‖r‖⁴
    reference: np.ndarray
    mean_sum: np.ndarray  # Σ (m_i − reference)
    mean_scatter: np.ndarray  # Σ (m_i − reference)(m_i − reference)ᵀ
    inverse_counts: float  # Σ 1 / n_i

    def minus(self, part: _Object) -> _Pooled:
        """These sums without one object's share."""
        c = part.mean - self.reference
        return replace(
            self,
            n_objects=self.n_objects - 1,
            n_rows=self.n_rows - part.count,
            scatter=self.scatter - part.scatter,
            quartic=self.quartic - part.quartic,
            mean_sum=self.mean_sum - c,
            mean_scatter=self.mean_scatter - np.outer(c, c),
            inverse_counts=self.inverse_counts - 1.0 / part.count,
        )

    def plus(self, part: _Object) -> _Pooled:
        c = part.mean - self.reference
        return replace(
            self,
            n_objects=self.n_objects + 1,
            n_rows=self.n_rows + part.count,
            scatter=self.scatter + part.scatter,
            quartic=self.quartic + part.quartic,
            mean_sum=self.mean_sum + c,
            mean_scatter=self.mean_scatter + np.outer(c, c),
            inverse_counts=self.inverse_counts + 1.0 / part.count,
        )


@dataclass(frozen=True)
class _Object:
    """One object's share of the sums: its rows' count, mean, residual scatter matrix, sum of
    squared residuals and of their squares squared."""

    count: int
    mean: np.ndarray
    scatter: np.ndarray
    own: float
    quartic: float

    @classmethod
    def of(cls, rows: np.ndarray) -> _Object:
        mean = rows.mean(axis=0)
        R = rows - mean
        sq = (R**2).sum(axis=1)
        return cls(rows.shape[0], mean, R.T @ R, float(sq.sum()), float((sq**2).sum()))


@dataclass(frozen=True)
class _Shape:
    """The model's shared parameters for a set of objects: the shrunk within-object covariance
    W (its Cholesky factor and log-determinant), the raw noise scale the per-object levels are
    measured in, the between-object covariance B and the centre of the means."""

    within: np.ndarray
    chol: np.ndarray
    logdet: float
    scale: float
    between: np.ndarray
    centre: np.ndarray
    n_objects: int

    @cached_property
    def _inverse_chol(self) -> np.ndarray:
        return np.linalg.inv(self.chol)

    def whiten(self, A: np.ndarray) -> np.ndarray:
        """Rows of ``A`` in W's whitened coordinates (L⁻¹ aᵀ, row by row). One inverse of the
        small factor, then products: a triangular solve per call costs more than the arithmetic
        at these sizes."""
        return np.atleast_2d(A) @ self._inverse_chol.T

    def levels(self, own: np.ndarray, counts: np.ndarray) -> np.ndarray:
        """Each object's noise relative to the pool, with one observation's worth of the pooled
        noise as its prior (objects observed once keep the pooled level)."""
        d = self.within.shape[0]
        return (own / self.scale + d) / ((counts - 1) * d + d)

    @cached_property
    def _between_in_noise(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """B in W's whitened coordinates, L⁻¹ B L⁻ᵀ = U diag(μ) Uᵀ: (U, μ, U ᵀ L⁻¹ centre).
        Then B + W/n = L U diag(μ + 1/n) Uᵀ Lᵀ for every n at once."""
        inv = self._inverse_chol
        M = inv @ self.between @ inv.T
        mu, U = np.linalg.eigh((M + M.T) / 2)
        return U, np.maximum(mu, 0.0), U.T @ (inv @ self.centre)

    def new_log_likelihood(self, means: np.ndarray, n: int | np.ndarray) -> np.ndarray:
        """log N(mean | centre, B + W/n) of each row of ``means`` (means of n observations;
        ``n`` one count, or one per row)."""
        U, mu, centre = self._between_in_noise
        y = self.whiten(means) @ U - centre
        n = np.asarray(n, dtype=np.float64).reshape(-1, 1)
        var = mu[None, :] + 1.0 / n
        d = mu.size
        return -0.5 * (
            (y**2 / var).sum(axis=1) + np.log(var).sum(axis=1) + self.logdet + d * np.log(2 * np.pi)
        )


def _ledoit_wolf(scatter: np.ndarray, quartic: float, n: int) -> float:
    """Ledoit and Wolf's shrinkage intensity of the residuals' covariance towards its average
    variance, from the residuals' scatter matrix Σ r rᵀ and Σ ‖r‖⁴ over their n rows (as
    ``sklearn.covariance.ledoit_wolf_shrinkage(R, assume_centered=True)`` computes it from R)."""
    d = scatter.shape[0]
    trace = float(np.trace(scatter)) / n
    mu = trace / d
    delta = float((scatter**2).sum()) / n**2
    beta = (quartic / n - delta) / (d * n)
    delta = (delta - 2.0 * mu * trace + d * mu**2) / d
    beta = min(beta, delta)
    return 0.0 if beta == 0 else beta / delta


def _shape(p: _Pooled) -> _Shape:
    d = p.scatter.shape[0]
    dof = p.n_rows - p.n_objects
    if p.n_objects < 2:
        raise InvalidInputError("an identity model needs at least two objects")
    if dof < 1:
        raise InvalidInputError("an identity model needs at least one repeated observation")
    W = p.scatter / dof
    scale = float(np.trace(W)) / d
    if not scale > 0:
        # Nothing to measure "how far apart two touches of one object lie" by: every odds of
        # being the same object would be 0/0.
        raise InvalidInputError(
            "the observations do not vary within any object (every repeat of a touch reads "
            "the same in every column): the library cannot tell how near a touch must be to "
            "be the same object"
        )
    # Few repeats in many columns leave the noise's covariance singular in some directions,
    # which would make "the same object" infinitely unlikely there: shrink it towards its
    # average variance by Ledoit and Wolf's intensity (as the metric's whitening does).
    if d > 1 and scale > 0:
        delta = _ledoit_wolf(p.scatter, p.quartic, p.n_rows)
        W = (1.0 - delta) * W + delta * scale * np.eye(d)
    # A column without any noise would still make W singular: give it a sliver.
    W = W + np.eye(d) * max(1e-9 * scale, 1e-300)
    # The objects' means span at most N − 1 of d directions: their covariance alone would
    # say that a new object can only lie where the old ones do. A prior worth d objects,
    # isotropic at the means' average variance, spreads it over every direction (the
    # conjugate normal-inverse-Wishart reading): the fewer objects, the rounder.
    N = p.n_objects
    shift = p.mean_sum / N
    centred = p.mean_scatter - N * np.outer(shift, shift)
    cov_means = centred / max(N - 1, 1)
    spread = float(np.trace(cov_means)) / d
    cov_means = ((N - 1) * cov_means + d * spread * np.eye(d)) / (N - 1 + d)
    B = cov_means - W * (p.inverse_counts / N)
    vals, vecs = np.linalg.eigh((B + B.T) / 2)
    floor = 1e-3 * max(float(np.mean(np.maximum(vals, 0.0))), scale)
    chol = np.linalg.cholesky(W)
    return _Shape(
        within=W,
        chol=chol,
        logdet=2.0 * float(np.log(np.diag(chol)).sum()),
        scale=scale,
        between=vecs @ np.diag(np.maximum(vals, floor)) @ vecs.T,
        centre=p.reference + shift,
        n_objects=N,
    )


def _old_log_likelihoods(
    shape: _Shape,
    white_means: np.ndarray,
    levels: np.ndarray,
    counts: np.ndarray,
    white_mean: np.ndarray,
    scatter: np.ndarray,
    n: int,
) -> np.ndarray:
    """``log p(V | old object i)`` for sets V of n observations, given by their means and their
    scatter around them in W's whitened coordinates (``white_mean`` (m, d), ``scatter`` (m,)),
    against objects given by their whitened means, levels and counts: (m, objects).

    V's mean ~ N(m_i, a_i W) with a_i = level_i (1/n + 1/n_i); the scatter around V's own mean
    is n − 1 directions' worth of N(0, level_i W)."""
    d = shape.within.shape[0]
    a = levels * (1.0 / n + 1.0 / counts)
    wm = np.atleast_2d(white_mean)
    sq = (wm**2).sum(axis=1)[:, None] + (white_means**2).sum(axis=1)[None, :]
    sq = np.maximum(sq - 2.0 * wm @ white_means.T, 0.0)
    scatter = np.asarray(scatter, dtype=np.float64)[:, None]
    return (
        -0.5 * sq / a
        - 0.5 * (d * np.log(2 * np.pi * a) + shape.logdet)
        - 0.5 * (scatter / levels + (n - 1) * (d * np.log(2 * np.pi * levels) + shape.logdet))
    )


def _new_log_likelihood(
    shape: _Shape, means: np.ndarray, scatter: np.ndarray, n: int
) -> np.ndarray:
    """``log p(V | new object)`` for sets V of n observations (their means, and their whitened
    scatter around them)."""
    d = shape.within.shape[0]
    scatter_term = -0.5 * (
        np.asarray(scatter, dtype=np.float64) + (n - 1) * (d * np.log(2 * np.pi) + shape.logdet)
    )
    return shape.new_log_likelihood(means, n) + scatter_term


class ObjectIdentity:
    """The library's two-covariance model, fitted on its observations (rows of ``X``, in the
    library's feature space) and their objects. Needs at least two objects and one repeated
    observation."""

    def __init__(self, X: np.ndarray, objects: np.ndarray) -> None:
        X = np.asarray(X, dtype=np.float64)
        labels = np.asarray(objects).astype(str)
        if X.ndim != 2 or labels.shape != (X.shape[0],):
            raise InvalidInputError(f"X must be (n, d) with one object per row, got {X.shape}")
        names, index, counts = np.unique(labels, return_inverse=True, return_counts=True)
        if names.size < 2:
            raise InvalidInputError("an identity model needs at least two objects")
        if X.shape[0] - names.size < 1:
            raise InvalidInputError("an identity model needs at least one repeated observation")
        d = X.shape[1]
        order = np.argsort(index, kind="stable")
        bounds = np.concatenate([[0], np.cumsum(counts)])
        #: Each object's rows, in the order given.
        self._rows = [order[bounds[k] : bounds[k + 1]] for k in range(names.size)]
        parts = [_Object.of(X[rows]) for rows in self._rows]
        means = np.array([p.mean for p in parts])
        reference = means.mean(axis=0)
        centred = means - reference
        self._pooled = _Pooled(
            n_objects=names.size,
            n_rows=X.shape[0],
            scatter=np.sum([p.scatter for p in parts], axis=0).reshape(d, d),
            quartic=float(sum(p.quartic for p in parts)),
            reference=reference,
            mean_sum=centred.sum(axis=0),
            mean_scatter=centred.T @ centred,
            inverse_counts=float(np.sum(1.0 / counts)),
        )
        self._parts = parts
        self._own = np.array([p.own for p in parts])
        self._shape = _shape(self._pooled)
        self.objects_ = [str(o) for o in names]
        self.means_ = means
        self.counts_ = counts
        self.noise_levels_ = self._shape.levels(self._own, counts)
        self.within_ = self._shape.within
        self.between_ = self._shape.between
        self.centre_ = self._shape.centre
        # The old objects' means in W's whitened coordinates: every "same object" density is a
        # scaled W, so one triangular solve serves them all.
        self._white_means = self._shape.whiten(means)
        self._impostors: np.ndarray | None = None
        self._X, self._labels = X, labels

    @property
    def n_features(self) -> int:
        return int(self.means_.shape[1])

    def _check(self, V: np.ndarray) -> np.ndarray:
        V = np.atleast_2d(np.asarray(V, dtype=np.float64))
        if V.ndim != 2 or V.shape[1] != self.n_features or V.shape[0] == 0:
            raise InvalidInputError(
                f"expected observations with {self.n_features} features, got shape {V.shape}"
            )
        return V

    def log_likelihoods(self, V: np.ndarray) -> tuple[np.ndarray, float]:
        """``log p(V | old object i)`` for every known object, and ``log p(V | new object)``,
        for the rows of ``V`` (observations of one object)."""
        V = self._check(V)
        n = V.shape[0]
        mean = V.mean(axis=0)
        Z = self._shape.whiten(V - mean)
        scatter = np.array([float((Z**2).sum())])
        old = _old_log_likelihoods(
            self._shape,
            self._white_means,
            self.noise_levels_,
            self.counts_,
            self._shape.whiten(mean),
            scatter,
            n,
        )[0]
        new = _new_log_likelihood(self._shape, mean[None, :], scatter, n)[0]
        return np.asarray(old, dtype=np.float64), float(new)

    def log_likelihoods_each(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`log_likelihoods` of every row of ``X`` on its own (one observation each):
        (rows, objects) and (rows,), computed together."""
        X = self._check(X)
        zero = np.zeros(X.shape[0])
        old = _old_log_likelihoods(
            self._shape,
            self._white_means,
            self.noise_levels_,
            self.counts_,
            self._shape.whiten(X),
            zero,
            1,
        )
        return old, _new_log_likelihood(self._shape, X, zero, 1)

    def _log_joint(self, V: np.ndarray, new_object_prior: float) -> np.ndarray:
        """Unnormalised log posterior: [new object, old object 0, 1, ...]."""
        if not 0.0 < new_object_prior < 1.0:
            raise InvalidInputError(f"new_object_prior must lie in (0, 1), got {new_object_prior}")
        old, new = self.log_likelihoods(V)
        return np.concatenate(
            [[np.log(new_object_prior) + new], np.log((1 - new_object_prior) / old.size) + old]
        )

    def log_posterior(
        self, V: np.ndarray, new_object_prior: float = NEW_OBJECT_PRIOR
    ) -> tuple[np.ndarray, float]:
        """``log P(old object i | V)`` for every known object and ``log P(new object | V)``."""
        joint = self._log_joint(V, new_object_prior)
        joint -= logsumexp(joint)
        return joint[1:], float(joint[0])

    def log_odds(
        self, V: np.ndarray, old_object: str, new_object_prior: float = NEW_OBJECT_PRIOR
    ) -> float:
        """The log posterior odds that the observations ``V`` are of ``old_object`` rather than
        of any other known object or of one not in the library."""
        try:
            i = self.objects_.index(str(old_object))
        except ValueError:
            raise UnknownNameError(f"{old_object!r} is not one of the library's objects") from None
        return _log_odds(self._log_joint(V, new_object_prior), 1 + i)

    def nearest(self, V: np.ndarray, k: int) -> np.ndarray:
        """The indices (into ``objects_``) of the ``k`` known objects most likely to have given
        the observations ``V``, most likely first."""
        old, _ = self.log_likelihoods(V)
        k = min(int(k), old.size)
        top = np.argpartition(-old, k - 1)[:k]
        return top[np.argsort(-old[top], kind="stable")]

    # -- the library judged by itself --------------------------------------------------------
    @cached_property
    def _neighbours(self) -> np.ndarray:
        """Each object's nearest other objects in the library's metric (its whitened means),
        nearest first: (objects, min(objects − 1, IMPOSTOR_COMPETITORS))."""
        from scipy.spatial import cKDTree

        k = min(len(self.objects_) - 1, IMPOSTOR_COMPETITORS)
        _, idx = cKDTree(self._white_means).query(self._white_means, k=k + 1)
        idx = np.atleast_2d(idx)
        out = np.empty((idx.shape[0], k), dtype=np.int64)
        for o in range(idx.shape[0]):
            others = idx[o][idx[o] != o]
            out[o] = others[:k]
        return out

    def _without_object(self, o: int) -> _Shape | None:
        """The shape of the library without object ``o`` (None where too little is left: fewer
        than two objects, or no repeated observation)."""
        p = self._pooled.minus(self._parts[o])
        if p.n_objects < 2 or p.n_rows - p.n_objects < 1:
            return None
        return _shape(p)

    def impostor_log_odds(self, n: int) -> float:
        """The largest log odds that one library object, left out of the library and presented
        as ``n`` of its observations (consecutive rows, every such set), receives for being some
        other library object: how alike the library's own distinct objects can look. A claim
        that a new object *is* an old one needs more than this (the same-object cut-off): a
        library whose objects include look-alikes asks for more evidence than one whose
        objects are far apart. Each left-out object competes against its
        :data:`IMPOSTOR_COMPETITORS` nearest objects (every object in a library of at most
        that many more). -inf where no object has ``n`` observations or leaving one out
        leaves fewer than two."""
        if n < 1:
            raise InvalidInputError(f"n must be >= 1, got {n}")
        if self._impostors is None:
            self._impostors = self.impostor_table()
        return float(self._impostors[n]) if n < self._impostors.size else -np.inf

    @property
    def impostors(self) -> np.ndarray | None:
        """:meth:`impostor_log_odds` of n = 0, 1, ... (entry 0: -inf), once computed or given."""
        return self._impostors

    @impostors.setter
    def impostors(self, table: np.ndarray) -> None:
        table = np.asarray(table, dtype=np.float64)
        if table.ndim != 1 or table.size != int(self.counts_.max()) + 1 or np.isnan(table).any():
            raise InvalidInputError(
                f"an impostor table of this library has {int(self.counts_.max()) + 1} values "
                f"(not NaN), got shape {table.shape}"
            )
        self._impostors = table

    def impostor_table(self, objects: np.ndarray | None = None) -> np.ndarray:
        """:meth:`impostor_log_odds` for n = 0 .. the largest object's count (entry 0: -inf),
        in one pass over the left-out ``objects`` (indices into ``objects_``; default all):
        each left-out library is fitted once, and every set of every size of the object's
        observations is scored at once. Tables of parts of the objects combine by their
        element-wise maximum."""
        most = int(self.counts_.max())
        best = np.full(most + 1, -np.inf)
        prior_new = np.log(NEW_OBJECT_PRIOR)
        prior_old = np.log((1 - NEW_OBJECT_PRIOR) / (len(self.objects_) - 1))
        neighbours = self._neighbours
        d = self.n_features
        chosen = range(len(self._rows)) if objects is None else [int(o) for o in objects]
        for o in chosen:
            rows = self._rows[o]
            shape = self._without_object(o)
            if shape is None:
                continue
            comps = neighbours[o]
            white = shape.whiten(self.means_[comps])
            levels = shape.levels(self._own[comps], self.counts_[comps])
            counts = self.counts_[comps]
            X = self._X[rows]
            Z = shape.whiten(X)
            # Every set of n consecutive observations, for every n: their sizes, means and
            # whitened scatter, from running sums.
            sizes, starts = _windows(rows.size)
            run = np.vstack([np.zeros(d), np.cumsum(X, axis=0)])
            run_z = np.vstack([np.zeros(d), np.cumsum(Z, axis=0)])
            run_sq = np.concatenate([[0.0], np.cumsum((Z**2).sum(axis=1))])
            ends = starts + sizes
            n = sizes.astype(np.float64)
            means = (run[ends] - run[starts]) / n[:, None]
            white_means = (run_z[ends] - run_z[starts]) / n[:, None]
            scatter = np.maximum(
                run_sq[ends] - run_sq[starts] - n * (white_means**2).sum(axis=1), 0
            )
            a = levels[None, :] * (1.0 / n[:, None] + 1.0 / counts[None, :])
            sq = _squared_distances(white_means, white)
            old = prior_old + (
                -0.5 * sq / a
                - 0.5 * (d * np.log(2 * np.pi * a) + shape.logdet)
                - 0.5
                * (
                    scatter[:, None] / levels[None, :]
                    + (n[:, None] - 1) * (d * np.log(2 * np.pi * levels[None, :]) + shape.logdet)
                )
            )
            new = (
                prior_new
                + shape.new_log_likelihood(means, n)
                - 0.5 * (scatter + (n - 1) * (d * np.log(2 * np.pi) + shape.logdet))
            )
            at = np.arange(n.size)
            top = np.argmax(old, axis=1)
            rest = old.copy()
            rest[at, top] = -np.inf
            odds = old[at, top] - _logsumexp_rows(np.column_stack([new, rest]))
            np.maximum.at(best, sizes, odds)
        return best

    def held_in_log_likelihoods(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For each of the given rows, its :meth:`log_likelihoods` under the library without
        that one observation: (rows, objects) — −inf for an object that observation was the only
        one of — and (rows,) for "new"."""
        rows = np.asarray(rows, dtype=np.int64)
        N = len(self.objects_)
        old = np.full((rows.size, N), -np.inf)
        new = np.zeros(rows.size)
        index = {str(o): k for k, o in enumerate(self.objects_)}
        for j, r in enumerate(rows):
            o = index[str(self._labels[r])]
            mine = self._rows[o]
            pooled = self._pooled.minus(self._parts[o])
            keep = mine[mine != r]
            part = _Object.of(self._X[keep]) if keep.size else None
            if part is not None:
                pooled = pooled.plus(part)
            if pooled.n_objects < 2 or pooled.n_rows - pooled.n_objects < 1:
                continue
            shape = _shape(pooled)
            own, counts, means = self._own.copy(), self.counts_.copy(), self.means_
            present = np.ones(N, dtype=bool)
            if part is None:
                present[o] = False
            else:
                own[o], counts[o] = part.own, part.count
                means = means.copy()
                means[o] = part.mean
            x = self._X[r][None, :]
            zero = np.zeros(1)
            cols = np.flatnonzero(present)
            old[j, cols] = _old_log_likelihoods(
                shape,
                shape.whiten(means[cols]),
                shape.levels(own[cols], counts[cols]),
                counts[cols],
                shape.whiten(x),
                zero,
                1,
            )[0]
            new[j] = _new_log_likelihood(shape, x, zero, 1)[0]
        return old, new

    def held_out_log_likelihoods(self, o: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Each observation of object ``o`` (index into ``objects_``) scored one by one by the
        library without that object: (its rows, objects) with −inf in column ``o``, and
        (rows,) for "new"; None where too little is left."""
        shape = self._without_object(o)
        if shape is None:
            return None
        N = len(self.objects_)
        cols = np.flatnonzero(np.arange(N) != o)
        X = self._X[self._rows[o]]
        zero = np.zeros(X.shape[0])
        old = np.full((X.shape[0], N), -np.inf)
        old[:, cols] = _old_log_likelihoods(
            shape,
            shape.whiten(self.means_[cols]),
            shape.levels(self._own[cols], self.counts_[cols]),
            self.counts_[cols],
            shape.whiten(X),
            zero,
            1,
        )
        return old, _new_log_likelihood(shape, X, zero, 1)

    def rows_of(self, o: int) -> np.ndarray:
        """The row indices of object ``o`` (index into ``objects_``) in the fitted ``X``."""
        return self._rows[o]


#: An impostor table is computed in at least this many parts of the objects, each process's.
IMPOSTOR_PARTS = 16


def impostor_parts(n_objects: int) -> list[np.ndarray]:
    """The parts of a library's objects an impostor table is computed in."""
    return [
        p for p in np.array_split(np.arange(n_objects), min(IMPOSTOR_PARTS, n_objects)) if p.size
    ]


def impostor_table(
    X: np.ndarray,
    objects: np.ndarray,
    parallel_map: Any = None,
    identity: ObjectIdentity | None = None,
    progress: Any = None,
) -> np.ndarray:
    """:meth:`ObjectIdentity.impostor_table` of the library of observations ``X`` of
    ``objects`` (its ``identity`` if at hand), its objects in :func:`impostor_parts`: here, or
    as ``parallel_map`` (an executor's ``imap_unordered``) runs them, each part sent the
    observations, not the model; ``progress.update(1)`` after each part."""
    parts = impostor_parts(len(np.unique(np.asarray(objects).astype(str))))
    tables = []
    if parallel_map is None:
        model = identity or ObjectIdentity(X, objects)
        results: Any = ((i, model.impostor_table(p)) for i, p in enumerate(parts))
    else:
        results = parallel_map(_impostor_part, [(X, objects, p) for p in parts])
    for _, table in results:
        tables.append(table)
        if progress is not None:
            progress.update(1)
    return np.maximum.reduce(tables)


def _impostor_part(task: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    X, objects, part = task
    return _fitted_once(X, objects).impostor_table(part)


#: The identity model of the library whose impostor parts this process computes.
_FITTED: dict[str, ObjectIdentity] = {}


def _fitted_once(X: np.ndarray, objects: np.ndarray) -> ObjectIdentity:
    """The identity model of these observations, fitted once per process (a process that
    computes several parts of one library's table fits it once)."""
    import hashlib

    labels = np.asarray(objects).astype(str)
    token = hashlib.sha256(
        np.ascontiguousarray(X).tobytes() + "\0".join(labels.tolist()).encode()
    ).hexdigest()
    if token not in _FITTED:
        _FITTED.clear()
        _FITTED[token] = ObjectIdentity(X, labels)
    return _FITTED[token]


def _windows(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Every set of n consecutive rows out of ``count``, for n = 1 .. count, the sets of one
    size side by side from the first row: (sizes, first rows)."""
    sizes = [np.full(count // n, n) for n in range(1, count + 1)]
    starts = [np.arange(count // n) * n for n in range(1, count + 1)]
    return np.concatenate(sizes).astype(np.int64), np.concatenate(starts).astype(np.int64)


def _squared_distances(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """‖a − b‖² of every row of ``A`` with every row of ``B``."""
    sq = (A**2).sum(axis=1)[:, None] + (B**2).sum(axis=1)[None, :] - 2.0 * A @ B.T
    return np.maximum(sq, 0.0)


def human_bytes(n: float) -> str:
    """Bytes as people read them: "1.6 TB", "512 MB" (as the core's memory checks say)."""
    for unit in ("bytes", "kB", "MB", "GB"):
        if n < 1000:
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} TB"


def _logsumexp_rows(a: np.ndarray) -> np.ndarray:
    """log Σ exp over each row (scipy's logsumexp costs more in its checks at these sizes)."""
    top = np.max(a, axis=1, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        return np.log(np.exp(a - top).sum(axis=1)) + top[:, 0]


def _log_odds(joint: np.ndarray, k: int) -> float:
    """log P(k) − log(1 − P(k)) from unnormalised log posteriors, without forming 1 − P(k)
    (which rounds to 0 where one hypothesis takes nearly all the mass)."""
    return float(joint[k] - logsumexp(np.delete(joint, k)))
