"""LaplaceGPC against scikit-learn's GaussianProcessClassifier and numerical integration."""

import numpy as np
import pytest
from scipy import integrate
from sklearn.gaussian_process import GaussianProcessClassifier
from sklearn.gaussian_process.kernels import RBF, ConstantKernel

from aptkt.gp import LaplaceGPC

from .conftest import make_blobs


def sklearn_fixed(X, y, s, l):
    kernel = ConstantKernel(s, "fixed") * RBF(l, "fixed")
    return GaussianProcessClassifier(kernel=kernel, optimizer=None).fit(X, y)


def sklearn_lmls(model):
    if hasattr(model.base_estimator_, "estimators_"):
        return np.array(
            [e.log_marginal_likelihood_value_ for e in model.base_estimator_.estimators_]
        )
    return np.array([model.base_estimator_.log_marginal_likelihood_value_])


@pytest.mark.parametrize(
    "n_per,n_classes,d,s,l,seed",
    [
        (20, 5, 8, 1.0, 1.0, 0),
        (30, 3, 12, 4.0, 2.5, 1),
        (40, 2, 5, 0.5, 0.7, 2),
        (15, 4, 22, 10.0, 6.0, 3),
    ],
)
def test_fixed_kernel_lml_and_probabilities_match_sklearn(n_per, n_classes, d, s, l, seed):
    X, y = make_blobs(n_per, n_classes, d, spread=1.5, seed=seed)
    ref = sklearn_fixed(X, y, s, l)
    ours = LaplaceGPC(length_scale=l, signal_variance=s, optimize=False).fit(X, y)
    assert ours.log_marginal_likelihood_.shape == (1 if n_classes == 2 else n_classes,)
    np.testing.assert_allclose(ours.log_marginal_likelihood_, sklearn_lmls(ref), rtol=1e-6)
    Xt = np.random.default_rng(seed + 100).normal(scale=2.5, size=(300, d))
    # Same predictive approximation as scikit-learn: agreement to rounding.
    np.testing.assert_allclose(ours.predict_proba(Xt), ref.predict_proba(Xt), atol=1e-6)
    # The accurate quadrature differs from the five-erf mixture only by that mixture's error.
    quad = LaplaceGPC(l, s, optimize=False, approximation="quadrature").fit(X, y)
    np.testing.assert_allclose(quad.predict_proba(Xt), ref.predict_proba(Xt), atol=1e-3)


def test_singular_kernel_from_duplicate_rows_is_fine():
    X, y = make_blobs(10, 3, 4, seed=5)
    X = np.concatenate([X, X])  # every row twice: K is singular, B = I + W½KW½ is not
    y = np.concatenate([y, y])
    ref = sklearn_fixed(X, y, 3.0, 1.2)
    ours = LaplaceGPC(1.2, 3.0, optimize=False).fit(X, y)
    np.testing.assert_allclose(ours.log_marginal_likelihood_, sklearn_lmls(ref), rtol=1e-6)
    assert np.all(ours.jitter_ == 0)


def test_quadrature_is_exact_against_scipy():
    X, y = make_blobs(25, 2, 3, spread=2.0, seed=7)
    model = LaplaceGPC(1.0, 8.0, optimize=False, approximation="quadrature").fit(X, y)
    Xt = np.random.default_rng(3).normal(scale=3, size=(25, 3))
    mean, var = model.latent(Xt)
    p = model.predict_proba(Xt)[:, 1]
    for m, v, got in zip(mean[:, 0], var[:, 0], p):
        sd = np.sqrt(v)
        want, _ = integrate.quad(
            lambda f, m=m, sd=sd: (
                np.exp(-0.5 * ((f - m) / sd) ** 2) / (sd * np.sqrt(2 * np.pi)) / (1 + np.exp(-f))
            ),
            m - 12 * sd,
            m + 12 * sd,
            epsabs=1e-13,
            epsrel=1e-12,
            limit=200,
        )
        assert got == pytest.approx(want, abs=1e-9)


def test_optimised_fit_reaches_sklearn_likelihood_with_same_starts():
    # Small (scikit-learn's optimiser is slow); held-out rows of the same blobs for testing.
    X_all, y_all = make_blobs(46, 5, 6, spread=1.8, seed=11)
    train = np.arange(len(y_all)) % 46 < 16
    X, y = X_all[train], y_all[train]
    ref = GaussianProcessClassifier(
        kernel=ConstantKernel(1.0) * RBF(1.0), n_restarts_optimizer=2, random_state=0
    ).fit(X, y)
    ours = LaplaceGPC(n_restarts=2, random_state=0).fit(X, y)
    # Per class, our best start is at least as good as scikit-learn's (small tolerance for the
    # optimisers' stopping rules).
    assert np.all(
        ours.log_marginal_likelihood_ >= sklearn_lmls(ref) - 1e-3 * np.abs(sklearn_lmls(ref))
    )
    Xt, yt = X_all[~train], y_all[~train]
    assert ours.score(Xt, yt) >= ref.score(Xt, yt) - 0.03
