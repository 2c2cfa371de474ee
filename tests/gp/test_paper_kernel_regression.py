"""The single-source dependent kernel reproduces the paper kernel of the implementation before
multi-source transfer (commit 6238510) exactly: predictions, latent moments, log marginal
likelihoods and their gradients are compared with values that implementation saved in
``data/paper_kernel_reference.npz`` (written by ``make_reference`` below)."""

from pathlib import Path

import numpy as np

from aptkt.gp import LaplaceGPC, TransferSource

REFERENCE = Path(__file__).with_name("data") / "paper_kernel_reference.npz"
MODALITIES = {"a": [0, 1], "b": [2, 3]}


def problem():
    rng = np.random.default_rng(2024)
    centers = rng.normal(scale=2.0, size=(3, 4))
    X = np.concatenate([c + rng.normal(size=(n, 4)) for c, n in zip(centers, (2, 7, 7))])
    y = np.repeat([0, 1, 2], (2, 7, 7))
    source = centers[0] + rng.normal(size=(12, 4))
    Xt = rng.normal(scale=2.5, size=(40, 4))
    theta = np.array([0.8, 0.2, -0.1, 0.3, -0.4, 0.7])
    return X, y, source, Xt, theta


def fits(X, y, source, make_source):
    fixed = LaplaceGPC([1.3, 0.9], 2.0, modalities=MODALITIES, optimize=False)
    fixed.fit(X, y, sources={0: make_source(source, 0.7)})
    # The defaults of the time, spelled out (they have changed since).
    fitted = LaplaceGPC(1.0, modalities=MODALITIES, n_restarts=2, max_iter=200, random_state=5)
    fitted.fit(X, y, sources={0: make_source(source, 0.6)})
    return fixed, fitted


def outputs(X, y, source, Xt, theta, make_source):
    fixed, fitted = fits(X, y, source, make_source)
    lml, grad = fixed.log_marginal_likelihood(theta, eval_gradient=True)
    out = {}
    for name, model in (("fixed", fixed), ("fitted", fitted)):
        mean, var = model.latent(Xt)
        out.update(
            {
                f"{name}_proba": model.predict_proba(Xt),
                f"{name}_mean": mean,
                f"{name}_var": var,
                f"{name}_theta": model.theta_,
                f"{name}_lml": model.log_marginal_likelihood_,
            }
        )
    out.update({"lml_at_theta": lml, "grad_at_theta": grad})
    return out


def make_reference():  # pragma: no cover - run once with the old implementation
    X, y, source, Xt, theta = problem()
    np.savez(REFERENCE, **outputs(X, y, source, Xt, theta, lambda s, lam: (s, lam)))


def test_single_positive_source_reproduces_the_saved_paper_kernel():
    X, y, source, Xt, theta = problem()
    got = outputs(X, y, source, Xt, theta, lambda s, lam: TransferSource(s, transfer_lambda=lam))
    with np.load(REFERENCE) as ref:
        assert set(ref.files) == set(got)
        for key in ref.files:
            if key.startswith("fixed") or key.endswith("at_theta"):
                np.testing.assert_allclose(got[key], ref[key], rtol=1e-11, atol=1e-13, err_msg=key)
            elif key == "fitted_lml":  # optimised: the same optimum...
                np.testing.assert_allclose(got[key], ref[key], rtol=1e-9, err_msg=key)
            else:
                # ...reached from the same starts, but the Newton search now reuses
                # factorisations (docs/gp.md), so the LML differs in its 12th digit and the
                # optimiser stops elsewhere within its tolerance on a flat ridge: θ moves by
                # ~1e-3 in directions the likelihood hardly sees, the predictions by ~1e-6.
                tol = {"fitted_theta": 5e-3}.get(key, 1e-5)
                np.testing.assert_allclose(got[key], ref[key], rtol=tol, atol=tol, err_msg=key)
