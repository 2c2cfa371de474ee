"""Hypothesis properties of the kernels and the classifier."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from aptkt.gp import LaplaceGPC, kernel_matrix

from .conftest import make_blobs

coords = st.floats(-5, 5, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(
    X=hnp.arrays(np.float64, st.tuples(st.integers(2, 14), st.just(4)), elements=coords),
    n_source=st.integers(0, 6),
    lam=st.floats(0, 1),
    log_sf2=st.floats(-2, 3),
    log_ls=st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5)),
    logits=st.tuples(st.floats(-3, 3), st.floats(-3, 3)),
)
def test_kernels_are_symmetric_psd_for_lambda_in_unit_interval(
    X, n_source, lam, log_sf2, log_ls, logits
):
    n_source = min(n_source, X.shape[0] - 1)
    theta = [log_sf2, *log_ls, *logits] + ([lam] if n_source else [])
    K = kernel_matrix(X, theta, modalities=[[0, 1], [2, 3]], n_source=n_source)
    np.testing.assert_array_equal(K, K.T)
    eig = np.linalg.eigvalsh(K)
    assert eig.min() >= -1e-10 * max(1.0, np.trace(K))


def test_lambda_outside_unit_interval_is_rejected():
    X = np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"lambda must lie in \[-1, 1\]"):
        kernel_matrix(X, [0.0, 0.0, 1.5], n_source=1)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    n_classes=st.integers(2, 4),
    approx=st.sampled_from(["erf", "quadrature"]),
)
def test_probabilities_are_a_distribution(seed, n_classes, approx):
    X, y = make_blobs(6, n_classes, 3, spread=1.5, seed=seed)
    model = LaplaceGPC(optimize=False, signal_variance=5.0, approximation=approx).fit(X, y)
    Xt = np.random.default_rng(seed).normal(scale=4, size=(40, 3))
    p = model.predict_proba(Xt)
    assert p.shape == (40, n_classes)
    assert np.all((p >= 0) & (p <= 1))
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-12)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), perm_seed=st.integers(0, 10_000))
def test_invariant_to_training_row_order(seed, perm_seed):
    X, y = make_blobs(8, 3, 3, spread=1.2, seed=seed)
    perm = np.random.default_rng(perm_seed).permutation(len(y))
    Xt = np.random.default_rng(seed + 1).normal(scale=3, size=(20, 3))
    a = LaplaceGPC(1.3, 2.0, optimize=False).fit(X, y)
    b = LaplaceGPC(1.3, 2.0, optimize=False).fit(X[perm], y[perm])
    np.testing.assert_allclose(a.log_marginal_likelihood_, b.log_marginal_likelihood_, rtol=1e-10)
    np.testing.assert_allclose(a.predict_proba(Xt), b.predict_proba(Xt), atol=1e-10)
    # The optimised model too (same starts: the data scale is order-free), up to optimiser noise.
    c = LaplaceGPC(random_state=0).fit(X, y)
    d = LaplaceGPC(random_state=0).fit(X[perm], y[perm])
    np.testing.assert_allclose(c.log_marginal_likelihood_, d.log_marginal_likelihood_, rtol=1e-4)
    np.testing.assert_allclose(c.predict_proba(Xt), d.predict_proba(Xt), atol=2e-3)
