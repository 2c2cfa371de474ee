"""Transfer sources: labelled (one-vs-all) sources, several sources per class in one block
kernel, weak hyper-priors (MAP-II), named fitted hyper-parameters, binary probabilities,
starting values and the save format."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.stats import norm
from sklearn.gaussian_process import GaussianProcessClassifier
from sklearn.gaussian_process.kernels import RBF, ConstantKernel

from aptkt.gp import HyperPrior, LaplaceGPC, TransferSource, kernel_matrix

from .conftest import make_blobs

coords = st.floats(-5, 5, allow_nan=False, allow_infinity=False)


# -- the multi-source block kernel ------------------------------------------------------------
@settings(max_examples=80, deadline=None)
@given(
    X=hnp.arrays(np.float64, st.tuples(st.integers(3, 16), st.just(3)), elements=coords),
    sizes=st.lists(st.integers(1, 4), min_size=1, max_size=4),
    lambdas=st.lists(st.floats(-1, 1), min_size=4, max_size=4),
    log_sf2=st.floats(-2, 3),
    log_ls=st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5)),
    logits=st.tuples(st.floats(-3, 3), st.floats(-3, 3)),
)
def test_multi_source_kernel_is_psd_for_lambdas_in_minus_one_one(
    X, sizes, lambdas, log_sf2, log_ls, logits
):
    while sum(sizes) >= X.shape[0]:
        sizes = sizes[:-1] if len(sizes) > 1 else [X.shape[0] - 1]
    theta = [log_sf2, *log_ls, *logits, *lambdas[: len(sizes)]]
    K = kernel_matrix(X, theta, modalities=[[0, 1], [2]], n_source=sizes)
    np.testing.assert_array_equal(K, K.T)
    assert np.linalg.eigvalsh(K).min() >= -1e-10 * max(1.0, np.trace(K))


def test_block_kernel_entries_follow_b():
    # B_tt = B_ss = 1, B_ts = λ_s, B_ss' = λ_s λ_s' times the plain kernel.
    X = np.random.default_rng(0).normal(size=(6, 2))
    lams = [0.3, -0.7]
    K = kernel_matrix(X, [0.4, 0.1, *lams], n_source=[2, 1])
    plain = kernel_matrix(X, [0.4, 0.1])
    task = np.array([0, 0, 1, 2, 2, 2])
    v = np.array([*lams, 1.0])
    B = np.outer(v, v) + np.diag([1 - lams[0] ** 2, 1 - lams[1] ** 2, 0.0])
    np.testing.assert_allclose(K, plain * B[task][:, task], rtol=1e-14, atol=1e-15)


def test_lambda_outside_minus_one_one_is_rejected():
    with pytest.raises(ValueError, match=r"\[-1, 1\]"):
        kernel_matrix(np.zeros((4, 2)), [0.0, 0.0, 0.5, 1.2], n_source=[1, 1])


# -- labelled sources ---------------------------------------------------------------------------
def _one_vs_all_problem(seed=3):
    rng = np.random.default_rng(seed)
    X, y = make_blobs(3, 3, 3, spread=1.0, seed=seed)
    src_pos = rng.normal(size=(6, 3)) + X[y == 0].mean(0)
    src_neg = rng.normal(size=(8, 3)) + X[y == 1].mean(0)
    Xs = np.vstack([src_pos, src_neg])
    ys = np.r_[np.ones(6), -np.ones(8)]
    return X, y, Xs, ys, rng.normal(scale=2.5, size=(30, 3))


def test_labelled_source_at_lambda_one_equals_sklearn_on_the_stacked_task():
    # With λ = 1 the block kernel is the plain kernel over source and target rows together, so
    # class 0's binary classifier is a plain GPC on [source; target] with labels [y_s; y == 0].
    X, y, Xs, ys, Xt = _one_vs_all_problem()
    ours = LaplaceGPC(1.3, 2.0, optimize=False).fit(
        X, y, sources={0: TransferSource(Xs, ys, transfer_lambda=1.0)}
    )
    ref = GaussianProcessClassifier(
        ConstantKernel(2.0, "fixed") * RBF(1.3, "fixed"), optimizer=None
    ).fit(np.vstack([Xs, X]), np.r_[ys > 0, y == 0])
    np.testing.assert_allclose(
        ours.predict_proba_binary(Xt)[:, 0], ref.predict_proba(Xt)[:, 1], atol=1e-6
    )
    np.testing.assert_allclose(
        ours.log_marginal_likelihood_[0], ref.log_marginal_likelihood_value_, rtol=1e-6
    )


def test_several_sources_at_lambda_one_equal_sklearn_on_all_rows_stacked():
    X, y, Xs, ys, Xt = _one_vs_all_problem(4)
    Xs2 = np.random.default_rng(9).normal(size=(5, 3))
    ys2 = np.array([1, 0, 1, 0, 0])  # 1/0 labels are read as +1/-1
    ours = LaplaceGPC(1.1, 1.5, optimize=False).fit(
        X,
        y,
        sources={2: [TransferSource(Xs, ys, transfer_lambda=1.0), TransferSource(Xs2, ys2, 1.0)]},
    )
    ref = GaussianProcessClassifier(
        ConstantKernel(1.5, "fixed") * RBF(1.1, "fixed"), optimizer=None
    ).fit(np.vstack([Xs, Xs2, X]), np.r_[ys > 0, ys2 > 0, y == 2])
    np.testing.assert_allclose(
        ours.predict_proba_binary(Xt)[:, 2], ref.predict_proba(Xt)[:, 1], atol=1e-6
    )
    assert ours.hyperparameter_names_[-2:] == ["transfer_lambda[0]", "transfer_lambda[1]"]


def test_a_source_at_lambda_zero_does_not_change_the_others():
    # λ_2 = 0 decouples source 2 from the target and from source 1 (B_12 = λ_1 λ_2 = 0): the
    # target predictions equal those with source 1 alone.
    X, y, Xs, ys, Xt = _one_vs_all_problem(5)
    Xs2 = np.random.default_rng(2).normal(size=(7, 3))
    one = LaplaceGPC(1.2, 2.0, optimize=False).fit(
        X, y, sources={1: TransferSource(Xs, ys, transfer_lambda=0.6)}
    )
    two = LaplaceGPC(1.2, 2.0, optimize=False).fit(
        X,
        y,
        sources={
            1: [
                TransferSource(Xs, ys, transfer_lambda=0.6),
                TransferSource(Xs2, transfer_lambda=0.0),
            ]
        },
    )
    np.testing.assert_allclose(two.predict_proba(Xt), one.predict_proba(Xt), atol=1e-10)


def test_one_vs_all_labels_change_the_prediction_against_positives_only():
    X, y, Xs, ys, _ = _one_vs_all_problem(6)
    pos = LaplaceGPC(1.0, 2.0, optimize=False).fit(
        X, y, sources={0: TransferSource(Xs[ys > 0], transfer_lambda=0.8)}
    )
    ova = LaplaceGPC(1.0, 2.0, optimize=False).fit(
        X, y, sources={0: TransferSource(Xs, ys, transfer_lambda=0.8)}
    )
    # The source's negatives lie around class 1: class 0's own probability drops there.
    near_1 = X[y == 1].mean(0) + np.random.default_rng(0).normal(scale=0.3, size=(20, 3))
    assert (
        ova.predict_proba_binary(near_1)[:, 0].mean()
        < pos.predict_proba_binary(near_1)[:, 0].mean() - 0.02
    )


@pytest.mark.parametrize(
    "y,error,match",
    [
        (np.array([1.0, np.nan, -1.0]), ValueError, "non-finite"),
        (np.array([1, 2, -1]), ValueError, "binary"),
        (np.array([1, -1]), ValueError, "one label per row"),
        (np.array(["a", "b", "a"]), TypeError, "numbers or booleans"),
        (0.7, TypeError, "transfer_lambda="),
    ],
)
def test_source_labels_are_validated(y, error, match):
    with pytest.raises(error, match=match):
        TransferSource(np.zeros((3, 2)), y, transfer_lambda=0.5)


def test_source_lambda_is_validated_and_required_when_fixed():
    X, y = make_blobs(4, 2, 2, seed=1)
    for bad in (-0.1, 1.5, np.nan):
        with pytest.raises(ValueError, match=r"\[0, 1\]"):
            TransferSource(X[:2], transfer_lambda=bad)
    with pytest.raises(ValueError, match="transfer_lambda is required"):
        LaplaceGPC().fit(X, y, sources={0: TransferSource(X[:2])})
    with pytest.raises(ValueError, match="features, expected 2"):
        LaplaceGPC().fit(X, y, sources={0: TransferSource(np.zeros((2, 3)), transfer_lambda=1)})
    # With λ free, a missing λ starts at 0.5 and is learned.
    model = LaplaceGPC(fixed=(), random_state=0).fit(X, y, sources={0: TransferSource(X[:2])})
    assert 0.0 <= model.theta_[0, -1] <= 1.0


# -- weak hyper-priors (MAP-II) -------------------------------------------------------------------
def _median_scale(X):
    d = np.sqrt(((X[:, None, :] - X[None, :, :]) ** 2).sum(-1))
    iu = np.triu_indices(len(X), 1)
    v = d[iu]
    v = np.sort(v[v > 0])
    return v[len(v) // 2]


def test_log_hyper_prior_matches_its_formula():
    X, y = make_blobs(8, 3, 4, seed=7)
    prior = HyperPrior(length_scale_centre=2.0, length_scale_sd=0.8, signal_variance_sd=1.5)
    model = LaplaceGPC(
        modalities=[[0, 1], [2, 3]], optimize=False, hyper_prior=prior, length_scale=[1.5, 0.7]
    ).fit(X, y)
    theta = model.theta_[0]
    want = norm.logpdf(theta[0], 0.0, 1.5)
    for m, cols in enumerate([[0, 1], [2, 3]]):
        want += norm.logpdf(theta[1 + m], np.log(2.0 * _median_scale(X[:, cols])), 0.8)
        # The weight logits (theta[3], theta[4]): centred on equal weights, ratio sd ln 10.
        want += norm.logpdf(theta[3 + m], 0.0, np.log(10.0) / np.sqrt(2.0))
    np.testing.assert_allclose(model.log_hyper_prior_, want, rtol=1e-12)
    np.testing.assert_allclose(
        model.log_marginal_likelihood(include_prior=True),
        model.log_marginal_likelihood_ + model.log_hyper_prior_,
    )


@pytest.mark.parametrize("latent_mean", ["zero", "base-rate"])
def test_map_objective_gradient_matches_finite_differences(latent_mean):
    """With the zero mean and with a constant latent mean (the gradient treats it as fixed)."""
    X, y = make_blobs(10, 3, 4, seed=8)
    source = make_blobs(5, 1, 4, seed=9)[0]
    model = LaplaceGPC(
        modalities=[[0, 1], [2, 3]],
        optimize=False,
        hyper_prior="weak",
        latent_mean=latent_mean,
        newton_tol=1e-14,
        newton_max_iter=200,
    ).fit(X, y, sources={1: TransferSource(source, transfer_lambda=0.6)})
    assert np.all((model.latent_offset_ != 0) == (latent_mean == "base-rate"))
    theta = np.tile([0.9, 0.1, -0.2, 0.3, -0.3, 0.45], (3, 1))
    _, grad = model.log_marginal_likelihood(theta, eval_gradient=True, include_prior=True)
    eps = 1e-5
    fd = np.zeros_like(theta)
    for p in range(theta.shape[1]):
        up, down = theta.copy(), theta.copy()
        up[:, p] += eps
        down[:, p] -= eps
        fd[:, p] = (
            model.log_marginal_likelihood(up, include_prior=True)
            - model.log_marginal_likelihood(down, include_prior=True)
        ) / (2 * eps)
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-6)
    # The prior's own gradient is not zero here: the test checks it, not only the LML's.
    _, lml_grad = model.log_marginal_likelihood(theta, eval_gradient=True)
    assert np.abs(grad - lml_grad).max() > 1e-3


def test_map_fit_maximises_the_posterior_and_ml_ii_is_unchanged():
    X, y = make_blobs(6, 3, 3, spread=2.0, seed=10)
    ml = LaplaceGPC(n_restarts=2, random_state=0).fit(X, y)
    assert np.all(ml.log_hyper_prior_ == 0)
    map_ = LaplaceGPC(n_restarts=2, random_state=0, hyper_prior="weak").fit(X, y)
    # MAP-II's optimum scores at least as well on its own objective as ML-II's optimum...
    at_ml = map_.log_marginal_likelihood(ml.theta_, include_prior=True)
    assert np.all(map_.log_marginal_likelihood(include_prior=True) >= at_ml - 1e-6)
    # ... and ML-II's optimum at least as well on the likelihood.
    assert np.all(ml.log_marginal_likelihood_ >= map_.log_marginal_likelihood_ - 1e-6)
    assert not np.allclose(ml.theta_, map_.theta_)


def test_hyper_prior_values_are_checked():
    X, y = make_blobs(4, 2, 2, seed=1)
    with pytest.raises(ValueError, match="hyper_prior must be"):
        LaplaceGPC(hyper_prior="strong").fit(X, y)
    with pytest.raises(ValueError, match="length_scale_sd"):
        HyperPrior(length_scale_sd=-1.0)
    with pytest.raises(ValueError, match="signal_variance_centre"):
        HyperPrior(signal_variance_centre=0.0)
    # A width of None leaves that hyper-parameter flat.
    flat_sv = LaplaceGPC(optimize=False, hyper_prior=HyperPrior(signal_variance_sd=None)).fit(X, y)
    both = LaplaceGPC(optimize=False, hyper_prior="weak").fit(X, y)
    assert flat_sv.log_hyper_prior_[0] - both.log_hyper_prior_[0] == pytest.approx(
        -norm.logpdf(0.0, 0.0, np.log(10.0))
    )
    with pytest.raises(ValueError, match="modality_weight_sd"):
        HyperPrior(modality_weight_sd=0.0)


def test_weak_weight_prior_keeps_an_ill_determined_model_on_both_modalities():
    # One observation per class: the likelihood barely depends on the modality weights, and
    # with flat weights the optimiser switches one modality off in some classifier.
    X, y = make_blobs(1, 6, 4, spread=2.0, seed=3)
    kw = dict(modalities=[[0, 1], [2, 3]], n_restarts=2, random_state=0)
    flat = LaplaceGPC(hyper_prior=HyperPrior(modality_weight_sd=None), **kw).fit(X, y)
    weak = LaplaceGPC(hyper_prior="weak", **kw).fit(X, y)

    def smallest_weight(model):
        return min(min(hp["modality_weights"].values()) for hp in model.hyperparameters_.values())

    assert smallest_weight(flat) < 0.01
    assert smallest_weight(weak) > 0.2
    # Where the data do tell the modalities apart, the prior does not hide it: columns 2-3
    # are pure noise, columns 0-1 separate the classes.
    rng = np.random.default_rng(5)
    Xi, yi = make_blobs(25, 2, 2, spread=0.4, seed=6)
    Xd = np.hstack([Xi, rng.normal(size=(Xi.shape[0], 2))])
    informed = LaplaceGPC(hyper_prior="weak", **kw).fit(Xd, yi)
    weights = next(iter(informed.hyperparameters_.values()))["modality_weights"]
    informative = list(weights.values())[0]
    assert informative > 0.75, weights


# -- named results, binary probabilities, starting values ------------------------------------
def test_hyperparameters_are_named_per_class_and_match_theta():
    X, y = make_blobs(6, 3, 4, seed=11)
    labels = np.array(["cup", "box", "tin"])[y]
    src = TransferSource(make_blobs(4, 1, 4, seed=12)[0], transfer_lambda=0.7, name="sponge")
    model = LaplaceGPC(modalities={"f": [0, 1], "t": [2, 3]}, random_state=0).fit(
        X, labels, sources={"box": src}
    )
    hp = model.hyperparameters_
    assert list(hp) == ["box", "cup", "tin"]
    box = hp["box"]
    assert set(box) == {"signal_variance", "length_scales", "modality_weights", "transfer_lambda"}
    assert box["transfer_lambda"] == {"sponge": pytest.approx(0.7)}
    assert hp["cup"]["transfer_lambda"] == {}
    assert box["signal_variance"] == pytest.approx(np.exp(model.theta_[0, 0]))
    assert list(box["length_scales"]) == ["f", "t"]
    assert sum(box["modality_weights"].values()) == pytest.approx(1.0)
    json.dumps(hp)  # plain, recordable values


def test_binary_probabilities_are_each_classifiers_own():
    X, y = make_blobs(6, 3, 3, seed=13)
    model = LaplaceGPC(1.0, 3.0, optimize=False).fit(X, y)
    Xt = np.random.default_rng(0).normal(scale=3, size=(25, 3))
    pb = model.predict_proba_binary(Xt)
    mean, var = model.latent(Xt)
    # Each column is σ integrated over that classifier's latent posterior: quadrature by hand.
    f = np.linspace(-12, 12, 4001)
    for c in range(3):
        dens = norm.pdf(f[None, :], mean[:, c : c + 1], np.sqrt(var[:, c : c + 1]))
        p = np.trapezoid(dens / (1 + np.exp(-f[None, :])), f, axis=1)
        np.testing.assert_allclose(pb[:, c], p, atol=2e-4)
    np.testing.assert_allclose(model.predict_proba(Xt), pb / pb.sum(1, keepdims=True))
    two = LaplaceGPC(1.0, 3.0, optimize=False).fit(X[y < 2], y[y < 2])
    p2 = two.predict_proba_binary(Xt)
    np.testing.assert_allclose(p2, two.predict_proba(Xt))


def test_starting_values_per_class():
    X, y = make_blobs(6, 3, 4, seed=14)
    mods = {"a": [0, 1], "b": [2, 3]}
    start = {
        1: {
            "signal_variance": 3.0,
            "length_scales": {"a": 0.5, "b": 2.0},
            "modality_weights": [1.0, 3.0],
        }
    }
    model = LaplaceGPC(modalities=mods, optimize=False).fit(X, y, hyperparameters=start)
    hp = model.hyperparameters_
    assert hp[1]["signal_variance"] == pytest.approx(3.0)
    assert hp[1]["length_scales"] == pytest.approx({"a": 0.5, "b": 2.0})
    assert hp[1]["modality_weights"] == pytest.approx({"a": 0.25, "b": 0.75})
    assert hp[0]["signal_variance"] == pytest.approx(1.0)  # the constructor's values
    # Fixed groups stay at the given values while the others are optimised.
    opt = LaplaceGPC(modalities=mods, fixed=("length_scale", "transfer_lambda"), random_state=0)
    opt.fit(X, y, hyperparameters=start)
    assert opt.hyperparameters_[1]["length_scales"] == pytest.approx({"a": 0.5, "b": 2.0})
    # A refit from a fit's own hyper-parameters starts at its optimum.
    first = LaplaceGPC(modalities=mods, random_state=0).fit(X, y)
    again = LaplaceGPC(modalities=mods, optimize=False).fit(
        X, y, hyperparameters=first.hyperparameters_
    )
    for attr in ("signal_variance_", "length_scales_", "modality_weights_"):
        np.testing.assert_allclose(getattr(again, attr), getattr(first, attr), rtol=1e-9)
    np.testing.assert_allclose(
        again.log_marginal_likelihood_, first.log_marginal_likelihood_, rtol=1e-9
    )
    with pytest.raises(ValueError, match="unknown key"):
        LaplaceGPC().fit(X, y, hyperparameters={0: {"gamma": 1}})
    with pytest.raises(ValueError, match="do not occur"):
        LaplaceGPC().fit(X, y, hyperparameters={7: {}})
    with pytest.raises(ValueError, match="> 0"):
        LaplaceGPC().fit(X, y, hyperparameters={0: {"signal_variance": -1}})


# -- persistence ----------------------------------------------------------------------------------
def test_save_round_trip_with_labelled_multi_sources_and_a_prior(tmp_path):
    X, y, Xs, ys, Xt = _one_vs_all_problem(15)
    model = LaplaceGPC(random_state=0, hyper_prior=HyperPrior(length_scale_sd=1.0)).fit(
        X,
        y,
        sources={
            0: [TransferSource(Xs, ys, 0.8, name="a"), TransferSource(Xs[:3], None, 0.4)],
            2: (Xs[:4], 0.3),
        },
    )
    path = tmp_path / "m.npz"
    model.save(path)
    loaded = LaplaceGPC.load(path)
    np.testing.assert_array_equal(loaded.theta_, model.theta_)
    np.testing.assert_allclose(loaded.predict_proba(Xt), model.predict_proba(Xt), rtol=1e-12)
    np.testing.assert_allclose(loaded.log_hyper_prior_, model.log_hyper_prior_, rtol=1e-12)
    assert loaded.hyperparameters_ == model.hyperparameters_
    assert loaded.hyper_prior == model.hyper_prior
    # A file from before the modality-weight prior: its hyper-prior had flat weights.
    state = model.state()
    meta = json.loads(bytes(state["meta"]).decode())
    del meta["params"]["hyper_prior"]["modality_weight_sd"]
    state["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    older = LaplaceGPC.from_state(state)
    assert older.hyper_prior.modality_weight_sd is None
    assert older.hyper_prior.length_scale_sd == 1.0


def _version_1_state(model):
    """The arrays the format-1 writer produced (one positives-only source per class)."""
    meta = {
        "format": "aptkt.LaplaceGPC/1",
        "params": {
            k: (list(v) if isinstance(v, tuple) else v)
            for k, v in model.get_params().items()
            if k not in ("random_state", "hyper_prior")
        },
        "classes": model.classes_.tolist(),
        "source_classes": list(model.sources_),
    }
    arrays = {
        "meta": np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
        "X": model.X_train_,
        "y": np.searchsorted(model.classes_, model.y_train_).astype(np.int64),
        "theta": model.theta_,
    }
    for i, (src,) in enumerate(model.sources_.values()):
        arrays[f"source_X_{i}"] = src.X
        arrays[f"source_lambda_{i}"] = np.asarray(src.transfer_lambda)
    return arrays


def test_format_1_files_are_still_read(tmp_path):
    X, y = make_blobs(6, 3, 3, seed=16)
    model = LaplaceGPC(random_state=0).fit(X, y, sources={1: (X[:4] + 0.1, 0.7)})
    path = tmp_path / "old.npz"
    np.savez(path, **_version_1_state(model))
    loaded = LaplaceGPC.load(path)
    Xt = np.random.default_rng(1).normal(size=(10, 3))
    np.testing.assert_allclose(loaded.predict_proba(Xt), model.predict_proba(Xt), rtol=1e-12)
    assert loaded.sources_[1][0].transfer_lambda == 0.7


def test_a_start_may_leave_length_scales_out():
    X, y = make_blobs(6, 3, 4, seed=14)
    mods = {"a": [0, 1], "b": [2, 3]}
    auto = LaplaceGPC(modalities=mods, optimize=False).fit(X, y)
    part = LaplaceGPC(modalities=mods, optimize=False).fit(
        X, y, hyperparameters={1: {"length_scales": {"a": 0.5}}}
    )
    # The one left out keeps its data-scaled value.
    assert part.hyperparameters_[1]["length_scales"] == pytest.approx(
        {"a": 0.5, "b": auto.hyperparameters_[1]["length_scales"]["b"]}
    )
    with pytest.raises(ValueError, match="must name the modalities"):
        LaplaceGPC(modalities=mods, optimize=False).fit(
            X, y, hyperparameters={1: {"length_scales": {"c": 0.5}}}
        )
