"""The Gaussian-mixture object similarity (Fig. 10) against scikit-learn's EM and by hand."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.experiments.similarity import (
    dissimilar_priors,
    fit_mixture,
    log_confusion,
    log_responsibilities,
    rescale,
)


def blobs(seed=0, n=25, d=3):
    """Four objects: 0 and 1 overlap, 2 and 3 far away from everything."""
    rng = np.random.default_rng(seed)
    centres = np.array([[0, 0, 0], [0.8, 0, 0], [8, 8, 0], [-8, 8, 0]], dtype=float)[:, :d]
    X = np.concatenate([c + rng.normal(size=(n, d)) for c in centres])
    return X, np.repeat(np.arange(4), n)


@pytest.mark.parametrize("kind", ["tied", "full", "diag"])
def test_em_matches_scikit_learn_from_the_same_start(kind):
    from sklearn import mixture

    X, labels = blobs()
    ours = fit_mixture(X, labels, 4, covariance_type=kind, tol=1e-3, max_iter=100)
    # The same initial parameters, given to scikit-learn explicitly.
    w0 = np.bincount(labels) / len(labels)
    m0 = np.array([X[labels == k].mean(0) for k in range(4)])
    d = X.shape[1]
    if kind == "tied":
        resid = X - m0[labels]
        p0 = np.linalg.inv(resid.T @ resid / len(X) + 1e-6 * np.eye(d))
    elif kind == "full":
        p0 = np.array(
            [
                np.linalg.inv(np.cov(X[labels == k].T, bias=True) + 1e-6 * np.eye(d))
                for k in range(4)
            ]
        )
    else:
        p0 = np.array([1 / (X[labels == k].var(0) + 1e-6) for k in range(4)])
    ref = mixture.GaussianMixture(
        4,
        covariance_type=kind,
        tol=1e-3,
        max_iter=100,
        reg_covar=1e-6,
        weights_init=w0,
        means_init=m0,
        precisions_init=p0,
    ).fit(X)
    assert ours.n_iter == ref.n_iter_
    assert ours.converged == ref.converged_
    np.testing.assert_allclose(ours.means, ref.means_, atol=1e-8)
    np.testing.assert_allclose(ours.weights, ref.weights_, atol=1e-10)
    np.testing.assert_allclose(
        np.exp(log_responsibilities(ours, X)), ref.predict_proba(X), atol=1e-8
    )
    assert ours.lower_bound == pytest.approx(ref.lower_bound_, abs=1e-8)


def test_confusion_by_hand_and_without_underflow():
    log_resp = np.log(np.array([[0.9, 0.1], [0.7, 0.3], [0.2, 0.8]]))
    C = np.exp(log_confusion(log_resp, [0, 0, 1], 2))
    np.testing.assert_allclose(C, [[0.8, 0.2], [0.2, 0.8]])
    # Responsibilities far below the smallest double stay ordered in logs.
    tiny = np.array([[0.0, -2000.0], [0.0, -1000.0], [-3000.0, 0.0]])
    L = log_confusion(tiny, [0, 0, 1], 2)
    assert L[0, 1] == pytest.approx(-1000 - np.log(2)) and L[1, 0] == pytest.approx(-3000)


def test_overlapping_objects_are_similar_and_far_ones_dissimilar():
    X, labels = blobs(n=40)
    fit = fit_mixture(X, labels, 4)
    L = log_confusion(log_responsibilities(fit, X), labels, 4)
    C = np.exp(L)
    assert C[0, 1] > 0.05 and C[1, 0] > 0.05  # 0 and 1 overlap
    assert C[2, 0] < 1e-6 and C[3, 1] < 1e-6
    # Priors 1..3 vs the "new" object 0: 1 resembles it; 2 and 3 do not.
    chosen, score = dissimilar_priors(L, ["a", "b", "c", "d"], ["b", "c", "d"], ["a"], 2)
    assert set(chosen) == {"c", "d"}
    assert score["b"] > score["c"] and score["b"] > score["d"]


def test_dissimilar_priors_use_both_directions_and_break_ties_by_order():
    S = np.array(
        [
            [1.0, 0.0, 0.4, 0.0],  # new object 0 is confused with prior 2 ...
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],  # ... but prior 2 is never confused with it: the mean is 0.2
            [0.1, 0.0, 0.0, 1.0],
        ]
    )
    with np.errstate(divide="ignore"):
        L = np.log(S)
    chosen, score = dissimilar_priors(L, ["n", "p1", "p2", "p3"], ["p1", "p2", "p3"], ["n"], 2)
    assert chosen == ["p1", "p3"]
    assert score["p2"] == pytest.approx(np.log10(0.2)) and score["p3"] == pytest.approx(
        np.log10(0.05)
    )
    chosen, _ = dissimilar_priors(np.zeros((3, 3)), ["n", "a", "b"], ["b", "a"], ["n"], 1)
    assert chosen == ["a"]  # a tie goes to the earlier object in the object order
    with pytest.raises(ValueError):
        dissimilar_priors(L, ["n", "p1", "p2", "p3"], ["p1"], ["n"], 2)


def test_rescale_and_input_errors():
    np.testing.assert_allclose(rescale([[0.2, 0.6], [1.0, 0.2]]), [[0, 0.5], [1, 0]])
    assert not rescale(np.full((2, 2), 0.3)).any()
    X, labels = blobs()
    with pytest.raises(ValueError, match="at least one initial sample"):
        fit_mixture(X, np.zeros(len(X), dtype=int), 2)
    with pytest.raises(ValueError, match="covariance_type"):
        fit_mixture(X, labels, 4, covariance_type="spherical-ish")
    bad = X.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        fit_mixture(bad, labels, 4)
