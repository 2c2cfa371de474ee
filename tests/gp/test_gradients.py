"""Analytic LML gradients against central finite differences, for every hyper-parameter."""

import numpy as np

from aptkt.gp import LaplaceGPC, TransferSource

from .conftest import make_blobs


def finite_difference(model, theta, eps=1e-5):
    grads = np.zeros_like(theta)
    for p in range(theta.shape[1]):
        up, down = theta.copy(), theta.copy()
        up[:, p] += eps
        down[:, p] -= eps
        grads[:, p] = (model.log_marginal_likelihood(up) - model.log_marginal_likelihood(down)) / (
            2 * eps
        )
    return grads


def check(model, theta):
    _, grad = model.log_marginal_likelihood(theta, eval_gradient=True)
    fd = finite_difference(model, theta)
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-6)


def test_single_modality():
    X, y = make_blobs(12, 3, 4, seed=1)
    model = LaplaceGPC(optimize=False, newton_tol=1e-14, newton_max_iter=200).fit(X, y)
    check(model, np.tile([0.7, 0.3], (3, 1)))


def test_multi_modal_weights_and_length_scales():
    X, y = make_blobs(12, 3, 5, seed=2)
    model = LaplaceGPC(
        modalities={"force": [0], "thermal": [1, 2], "texture": [3, 4]},
        optimize=False,
        newton_tol=1e-14,
        newton_max_iter=200,
    ).fit(X, y)
    assert model.hyperparameter_names_ == [
        "log_signal_variance",
        "log_length_scale[force]",
        "log_length_scale[thermal]",
        "log_length_scale[texture]",
        "weight_logit[force]",
        "weight_logit[thermal]",
        "weight_logit[texture]",
    ]
    check(model, np.tile([1.2, -0.3, 0.2, 0.5, 0.4, -0.8, 0.1], (3, 1)))


def test_transfer_kernel_including_lambda():
    X, y = make_blobs(8, 3, 4, seed=3)
    source = make_blobs(6, 1, 4, seed=4)[0]
    model = LaplaceGPC(
        modalities=[[0, 1], [2, 3]], optimize=False, newton_tol=1e-14, newton_max_iter=200
    ).fit(X, y, sources={1: TransferSource(source, transfer_lambda=0.6)})
    assert model.hyperparameter_names_[-1] == "transfer_lambda"
    theta = np.tile([0.9, 0.1, -0.2, 0.3, -0.3, 0.45], (3, 1))
    check(model, theta)
    # Only class 1 has a source: λ cannot matter to the others.
    _, grad = model.log_marginal_likelihood(theta, eval_gradient=True)
    assert grad[0, -1] == 0 and grad[2, -1] == 0 and grad[1, -1] != 0
