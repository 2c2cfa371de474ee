"""The constant latent prior mean (``LaplaceGPC(latent_mean="base-rate")``), checked against an
independent NumPy Laplace approximation written in f-space with the mean function (GPML §2.7,
§3.4) and against closed forms. (Its gradient against finite differences: test_transfer.py.)"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate
from scipy.special import expit, log_expit

from aptkt.gp import LaplaceGPC, kernel_matrix

from .conftest import make_blobs


def jeffreys_offset(y_pm):
    """logit of (n₊ + ½) / (n + 1)."""
    pos = float(np.sum(np.asarray(y_pm) > 0))
    return np.log((pos + 0.5) / (len(y_pm) - pos + 0.5))


def laplace_with_mean(K, y_pm, m, iters=200):
    """Newton on Ψ(f) = log p(y|f) − ½ (f − m)ᵀ K⁻¹ (f − m) with explicit inverses (small n):
    f ← (K⁻¹ + W)⁻¹ (W f + ∇log p(y|f) + K⁻¹ m). Returns the mode, ∇log p at it, W and the
    Laplace log marginal likelihood."""
    n = len(y_pm)
    t = (np.asarray(y_pm) + 1) / 2
    Kinv = np.linalg.inv(K)
    f = np.full(n, m, dtype=float)
    for _ in range(iters):
        pi = expit(f)
        W = np.diag(pi * (1 - pi))
        f_new = np.linalg.solve(Kinv + W, W @ f + (t - pi) + Kinv @ np.full(n, m))
        if np.max(np.abs(f_new - f)) < 1e-13:
            f = f_new
            break
        f = f_new
    pi = expit(f)
    w = pi * (1 - pi)
    sw = np.sqrt(w)
    B = np.eye(n) + sw[:, None] * K * sw[None, :]
    d = f - m
    lml = -0.5 * d @ Kinv @ d + np.sum(log_expit(y_pm * f)) - 0.5 * np.linalg.slogdet(B)[1]
    return f, t - pi, w, lml


def test_fit_and_predictions_match_an_independent_laplace_with_a_mean():
    X, y = make_blobs(6, 3, 3, spread=1.2, seed=5)
    X = X[:14]  # unequal counts: 6, 6, 2
    y = y[:14]
    Xs = make_blobs(4, 3, 3, spread=1.5, seed=6)[0]
    theta = np.array([0.7, 0.3])  # log σ², log ℓ
    model = LaplaceGPC(
        length_scale=np.exp(0.3),
        signal_variance=np.exp(0.7),
        optimize=False,
        latent_mean="base-rate",
        newton_tol=1e-14,
        newton_max_iter=200,
    ).fit(X, y)
    K_all = kernel_matrix(np.vstack([X, Xs]), theta)
    n = len(X)
    K, Ks, Kss = K_all[:n, :n], K_all[n:, :n], np.diag(K_all[n:, n:])
    mean, var = model.latent(Xs)
    for c in range(3):
        y_pm = np.where(y == c, 1.0, -1.0)
        m = jeffreys_offset(y_pm)
        assert model.latent_offset_[c] == pytest.approx(m, abs=1e-12)
        _, grad, w, lml = laplace_with_mean(K, y_pm, m)
        assert model.log_marginal_likelihood_[c] == pytest.approx(lml, rel=1e-9, abs=1e-9)
        np.testing.assert_allclose(mean[:, c], m + Ks @ grad, rtol=1e-8, atol=1e-9)
        want_var = Kss - np.einsum("ij,ij->i", Ks @ np.linalg.inv(K + np.diag(1 / w)), Ks)
        np.testing.assert_allclose(var[:, c], want_var, rtol=1e-7, atol=1e-9)
    # The zero mean is the same reference at m = 0.
    zero = LaplaceGPC(length_scale=np.exp(0.3), signal_variance=np.exp(0.7), optimize=False).fit(
        X, y
    )
    y_pm = np.where(y == 2, 1.0, -1.0)
    assert zero.log_marginal_likelihood_[2] == pytest.approx(
        laplace_with_mean(K, y_pm, 0.0)[3], rel=1e-9
    )
    assert np.all(zero.latent_offset_ == 0)


@settings(max_examples=25, deadline=None)
@given(counts=st.lists(st.integers(1, 7), min_size=2, max_size=5), seed=st.integers(0, 1000))
def test_far_from_the_data_each_classifier_returns_to_its_base_rate(counts, seed):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(sum(counts), 2))
    y = np.repeat(np.arange(len(counts)), counts)
    model = LaplaceGPC(optimize=False, latent_mean="base-rate", approximation="quadrature").fit(
        X, y
    )
    far = np.array([[1e4, -1e4]])
    binary = model.predict_proba_binary(far)[0]
    sd = np.sqrt(model.signal_variance_)
    single = len(counts) == 2  # one classifier (class 1 positive) serves both classes
    for c in range(len(counts)):
        pos = counts[c]
        r = 0 if single else c
        m = np.log((pos + 0.5) / (sum(counts) - pos + 0.5))
        # k* = 0: the prior predictive ∫ σ(f) N(f | m, σ²) df.
        want = integrate.quad(
            lambda f, m=m, s=sd[r]: (
                expit(f) * np.exp(-0.5 * ((f - m) / s) ** 2) / (s * np.sqrt(2 * np.pi))
            ),
            m - 12 * sd[r],
            m + 12 * sd[r],
        )[0]
        assert binary[c] == pytest.approx(want, abs=1e-7)
        # The base rate the uniform class prior moves stays the training frequency.
        assert model.base_rates_[c] == pytest.approx(pos / sum(counts))
    if len(set(counts)) == 1:
        # Equal counts: the uniform class prior changes nothing, with the mean too.
        np.testing.assert_allclose(
            model.predict_proba(far, class_prior="uniform"), model.predict_proba(far), rtol=1e-12
        )


def test_a_mean_keeps_an_old_classifier_from_claiming_unlike_observations():
    """The relatedness of Eq. 3 is an old classifier's p(y = +1 | v). Observations unlike any
    old object's get ½ from a zero-mean classifier, which passes ε_neg = 0.5's tie; with the
    base-rate mean they get about the classifier's base rate."""
    X, y = make_blobs(8, 5, 3, spread=0.5, seed=2)
    unlike = X.mean(axis=0) + 40.0 + np.random.default_rng(1).normal(size=(6, 3))
    for latent_mean, low, high in (("zero", 0.49, 0.51), ("base-rate", 0.0, 0.45)):
        model = LaplaceGPC(latent_mean=latent_mean, hyper_prior="weak", random_state=0).fit(X, y)
        p_bar = model.predict_proba_binary(unlike).mean(axis=0)
        assert np.all((low < p_bar) & (p_bar < high)), (latent_mean, p_bar)
        # Near their own data both readings claim their own objects.
        own = model.predict_proba_binary(X)[np.arange(len(y)), y]
        assert own.mean() > 0.7


def test_invalid_latent_mean_is_refused():
    X, y = make_blobs(3, 2, 2)
    with pytest.raises(ValueError, match="latent_mean must be one of"):
        LaplaceGPC(latent_mean="constant").fit(X, y)


def test_save_round_trip_keeps_the_mean_and_the_default_is_left_out(tmp_path):
    X, y = make_blobs(4, 3, 2, seed=3)
    X, y = X[:10], y[:10]
    model = LaplaceGPC(latent_mean="base-rate", class_prior="uniform", random_state=0).fit(X, y)
    model.save(tmp_path / "m.npz")
    back = LaplaceGPC.load(tmp_path / "m.npz")
    assert back.latent_mean == "base-rate"
    np.testing.assert_array_equal(back.latent_offset_, model.latent_offset_)
    np.testing.assert_allclose(back.predict_proba(X), model.predict_proba(X), rtol=1e-12)
    import json

    zero = LaplaceGPC(random_state=0).fit(X, y)
    meta = json.loads(bytes(zero.state()["meta"]).decode())
    assert "latent_mean" not in meta["params"]
    meta = json.loads(bytes(model.state()["meta"]).decode())
    assert meta["params"]["latent_mean"] == "base-rate"
