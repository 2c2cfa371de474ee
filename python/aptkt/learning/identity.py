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
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.special import logsumexp
from sklearn.covariance import ledoit_wolf_shrinkage

from aptkt.errors import InvalidInputError, UnknownNameError

__all__ = ["ObjectIdentity", "NEW_OBJECT_PRIOR"]

#: Prior probability that an object presented to the robot is not one of the library's: as
#: likely as not — neither the library nor the lab knows better before the first touch.
NEW_OBJECT_PRIOR = 0.5


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
        n, d = X.shape
        dof = n - names.size
        if dof < 1:
            raise InvalidInputError("an identity model needs at least one repeated observation")
        means = np.zeros((names.size, d))
        np.add.at(means, index, X)
        means /= counts[:, None]
        R = X - means[index]
        W = R.T @ R / dof
        scale = np.trace(W) / d
        # Few repeats in many columns leave the noise's covariance singular in some directions,
        # which would make "the same object" infinitely unlikely there: shrink it towards its
        # average variance by Ledoit and Wolf's intensity (as the metric's whitening does).
        if d > 1 and scale > 0:
            delta = float(ledoit_wolf_shrinkage(R, assume_centered=True))
            W = (1.0 - delta) * W + delta * scale * np.eye(d)
        # A column without any noise would still make W singular: give it a sliver.
        W = W + np.eye(d) * max(1e-9 * scale, 1e-300)
        own = np.zeros(names.size)
        np.add.at(own, index, (R**2).sum(axis=1))
        own_dof = (counts - 1) * d
        # Each object's noise relative to the pool, with one observation's worth of the pooled
        # noise as its prior (objects observed once keep the pooled level).
        levels = (own / scale + d) / (own_dof + d)
        # The objects' means span at most N − 1 of d directions: their covariance alone would
        # say that a new object can only lie where the old ones do. A prior worth d objects,
        # isotropic at the means' average variance, spreads it over every direction (the
        # conjugate normal-inverse-Wishart reading): the fewer objects, the rounder.
        centred = means - means.mean(axis=0)
        cov_means = centred.T @ centred / max(names.size - 1, 1)
        spread = np.trace(cov_means) / d
        cov_means = ((names.size - 1) * cov_means + d * spread * np.eye(d)) / (names.size - 1 + d)
        B = cov_means - W * float(np.mean(1.0 / counts))
        vals, vecs = np.linalg.eigh((B + B.T) / 2)
        floor = 1e-3 * max(float(np.mean(np.maximum(vals, 0.0))), scale)
        self.objects_ = [str(o) for o in names]
        self.means_ = means
        self.counts_ = counts
        self.noise_levels_ = levels
        self.within_ = W
        self.between_ = vecs @ np.diag(np.maximum(vals, floor)) @ vecs.T
        self.centre_ = means.mean(axis=0)
        self._W_chol = np.linalg.cholesky(W)
        self._W_logdet = 2.0 * float(np.log(np.diag(self._W_chol)).sum())
        # The old objects' means in W's whitened coordinates: every "same object" density is a
        # scaled W, so one triangular solve serves them all.
        self._white_means = np.linalg.solve(self._W_chol, means.T).T
        self._impostors: dict[int, float] = {}
        self._left_out: dict[str, ObjectIdentity] = {}
        self._X, self._labels = X, labels

    @property
    def n_features(self) -> int:
        return int(self.means_.shape[1])

    def log_likelihoods(self, V: np.ndarray) -> tuple[np.ndarray, float]:
        """``log p(V | old object i)`` for every known object, and ``log p(V | new object)``,
        for the rows of ``V`` (observations of one object)."""
        V = np.atleast_2d(np.asarray(V, dtype=np.float64))
        if V.ndim != 2 or V.shape[1] != self.n_features or V.shape[0] == 0:
            raise InvalidInputError(
                f"expected observations with {self.n_features} features, got shape {V.shape}"
            )
        n, d = V.shape
        mean = V.mean(axis=0)
        # The scatter around V's own mean: the same under every hypothesis but for the noise
        # level it is measured in — n − 1 directions' worth of N(0, level W).
        Z = np.linalg.solve(self._W_chol, (V - mean).T)
        scatter = float((Z**2).sum())
        logdet = self._W_logdet

        def scatter_term(level: Any) -> Any:
            return -0.5 * (scatter / level + (n - 1) * (d * np.log(2 * np.pi * level) + logdet))

        # Same object i: V's mean ~ N(m_i, a_i W) with a_i = level_i (1/n + 1/n_i).
        a = self.noise_levels_ * (1.0 / n + 1.0 / self.counts_)
        z = np.linalg.solve(self._W_chol, mean) - self._white_means
        old = (
            -0.5 * (z**2).sum(axis=1) / a
            - 0.5 * (d * np.log(2 * np.pi * a) + logdet)
            + scatter_term(self.noise_levels_)
        )
        new = _log_normal(mean, self.centre_, self.between_ + self.within_ / n) + scatter_term(1.0)
        return np.asarray(old, dtype=np.float64), float(new)

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

    def impostor_log_odds(self, n: int) -> float:
        """The largest log odds that one library object, left out of the library and presented
        as ``n`` of its observations (consecutive rows, every such set), receives for being some
        other library object: how alike the library's own distinct objects can look. A claim
        that a new object *is* an old one needs more than this (the same-object cut-off): a
        library whose objects include look-alikes asks for more evidence than one whose
        objects are far apart. -inf where no object has ``n`` observations or leaving one
        out leaves fewer than two."""
        if n < 1:
            raise InvalidInputError(f"n must be >= 1, got {n}")
        if n not in self._impostors:
            best = -np.inf
            for o in self.objects_:
                keep = self._labels != o
                rows = self._X[~keep]
                others = self._labels[keep]
                if rows.shape[0] < n or len(set(others.tolist())) < 2:
                    continue
                if others.size == len(set(others.tolist())):
                    continue  # no repeats left: no noise to judge by
                model = self._without(o, keep)
                for start in range(0, rows.shape[0] - n + 1, n):
                    joint = model._log_joint(rows[start : start + n], NEW_OBJECT_PRIOR)
                    best = max(best, _log_odds(joint, 1 + int(np.argmax(joint[1:]))))
            self._impostors[n] = best
        return self._impostors[n]

    def _without(self, o: str, keep: np.ndarray) -> ObjectIdentity:
        """The library's model without object ``o`` (rows ``keep``), fitted once for every
        number of observations the impostors are judged at."""
        if o not in self._left_out:
            self._left_out[o] = ObjectIdentity(self._X[keep], self._labels[keep])
        return self._left_out[o]


def _log_odds(joint: np.ndarray, k: int) -> float:
    """log P(k) − log(1 − P(k)) from unnormalised log posteriors, without forming 1 − P(k)
    (which rounds to 0 where one hypothesis takes nearly all the mass)."""
    return float(joint[k] - logsumexp(np.delete(joint, k)))


def _log_normal(x: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> float:
    L = np.linalg.cholesky(cov)
    z = np.linalg.solve(L, x - mean)
    return float(-0.5 * z @ z - np.log(np.diag(L)).sum() - 0.5 * x.size * np.log(2 * np.pi))
