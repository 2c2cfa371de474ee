"""LaplaceGPC's estimator conventions, errors, transfer behaviour and persistence."""

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.utils.multiclass import check_classification_targets

from aptkt.gp import LaplaceGPC, TransferSource
from aptkt.gp.inputs import check_classification_targets as fast_check

from .conftest import make_blobs


def test_params_round_trip_and_clone():
    model = LaplaceGPC(
        length_scale="auto", n_restarts=4, modalities={"a": [0], "b": [1, 2]}, random_state=3
    )
    params = model.get_params()
    assert params["n_restarts"] == 4 and params["length_scale"] == "auto"
    copy = clone(model)
    assert copy.get_params() == params
    model.set_params(n_restarts=3)
    assert model.n_restarts == 3
    with pytest.raises(ValueError, match="Invalid parameter 'bogus'"):
        model.set_params(bogus=1)
    assert "n_restarts=3" in repr(model)


def test_fitted_attributes_have_documented_shapes():
    X, y = make_blobs(10, 4, 3, spread=0.5, seed=1)
    labels = np.array(["cup", "sponge", "box", "tin"])[y]
    model = LaplaceGPC(modalities=[[0], [1, 2]], random_state=0).fit(X, labels)
    assert list(model.classes_) == sorted(set(labels))
    assert model.theta_.shape == (4, 5)
    assert model.log_marginal_likelihood_.shape == (4,)
    assert model.length_scales_.shape == (4, 2)
    np.testing.assert_allclose(model.modality_weights_.sum(axis=1), 1.0)
    assert set(model.predict(X)) <= set(labels)
    assert model.score(X, labels) > 0.8
    np.testing.assert_allclose(model.log_marginal_likelihood(), model.log_marginal_likelihood_)


def test_same_random_state_same_fit_and_different_states_may_differ():
    X, y = make_blobs(10, 3, 4, seed=2)
    a = LaplaceGPC(n_restarts=3, random_state=7).fit(X, y)
    b = LaplaceGPC(n_restarts=3, random_state=7).fit(X, y)
    np.testing.assert_array_equal(a.theta_, b.theta_)


def test_data_scaled_start_rescues_badly_scaled_features():
    # Features in the thousands: a lone start at length-scale 1 sits on a flat plateau where
    # every kernel entry is 0; the data-scaled start finds the structure.
    X, y = make_blobs(15, 3, 4, spread=1.0, seed=3)
    X = X * 1000.0
    lone = LaplaceGPC(1.0, n_restarts=0, random_state=0).fit(X, y)
    scaled = LaplaceGPC(1.0, n_restarts=1, random_state=0).fit(X, y)
    assert np.all(scaled.log_marginal_likelihood_ >= lone.log_marginal_likelihood_ - 1e-9)
    assert scaled.log_marginal_likelihood_.sum() > lone.log_marginal_likelihood_.sum() + 5
    Xt, yt = make_blobs(15, 3, 4, spread=1.0, seed=3)
    assert scaled.score(Xt * 1000.0, yt) > 0.9


def test_bad_input_errors():
    X, y = make_blobs(5, 2, 3, seed=4)
    with pytest.raises(ValueError, match="at least two classes"):
        LaplaceGPC().fit(X, np.zeros(len(X)))
    with pytest.raises(ValueError, match="inconsistent numbers of samples"):
        LaplaceGPC().fit(X, y[:-1])
    Xn = X.copy()
    Xn[2, 1] = np.nan
    with pytest.raises(ValueError, match="row 2, column 1"):
        LaplaceGPC().fit(Xn, y)
    model = LaplaceGPC(optimize=False).fit(X, y)
    with pytest.raises(ValueError, match="X has 4 features, but LaplaceGPC is expecting 3"):
        model.predict_proba(np.zeros((2, 4)))
    with pytest.raises(ValueError, match="non-finite"):
        model.predict_proba(np.full((1, 3), np.inf))
    with pytest.raises(ValueError, match="does not occur in y"):
        LaplaceGPC().fit(X, y, sources={9: TransferSource(X[:2], transfer_lambda=0.5)})
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        LaplaceGPC().fit(X, y, sources={1: (X[:2], 1.5)})
    with pytest.raises(ValueError, match="unknown hyper-parameter"):
        LaplaceGPC(fixed=("gamma",)).fit(X, y)
    with pytest.raises(ValueError, match="approximation"):
        LaplaceGPC(approximation="probit").fit(X, y)
    with pytest.raises(AttributeError, match="not fitted"):
        LaplaceGPC().predict(X)
    for tol in (-1e-6, float("nan"), float("inf"), "1e-6", True):
        with pytest.raises(ValueError, match="optimizer_tol"):
            LaplaceGPC(optimizer_tol=tol).fit(X, y)


def test_optimizer_tolerance_stops_the_search_earlier_and_only_where_it_barely_moves():
    """scipy's rule by default; a looser relative tolerance takes fewer evaluations and ends
    within that tolerance's reach of the tight optimum (MAP-II objective, which is concave
    enough near the optimum for the bound to hold in this well-conditioned problem)."""
    X, y = make_blobs(12, 3, 3, spread=1.0, seed=7)
    common = dict(n_restarts=0, hyper_prior="weak", random_state=0)
    tight = LaplaceGPC(**common).fit(X, y)
    assert LaplaceGPC().optimizer_tol == pytest.approx(1e7 * np.finfo(float).eps)
    loose = LaplaceGPC(optimizer_tol=1e-3, **common).fit(X, y)
    assert loose.n_evaluations_.sum() < tight.n_evaluations_.sum()
    objective = lambda m: m.log_marginal_likelihood_ + m.log_hyper_prior_  # noqa: E731
    gap = objective(tight) - objective(loose)
    assert np.all(gap >= -1e-9)  # the tight search is never worse
    assert np.all(gap <= 0.05 * np.abs(objective(tight)))
    # A tolerance nothing can meet stops each classifier after its first step.
    first = LaplaceGPC(optimizer_tol=1e6, **common).fit(X, y)
    assert np.all(first.n_iter_ <= 1)


def test_lambda_zero_transfer_equals_no_transfer():
    # With λ = 0 the dependent kernel is block-diagonal: the source block cannot change the
    # posterior of the target block, so predictions equal those without a source.
    X, y = make_blobs(8, 3, 3, seed=5)
    source = make_blobs(10, 1, 3, seed=6)[0]
    Xt = np.random.default_rng(1).normal(scale=3, size=(30, 3))
    plain = LaplaceGPC(1.1, 2.0, optimize=False).fit(X, y)
    zero = LaplaceGPC(1.1, 2.0, optimize=False).fit(X, y, sources={0: (source, 0.0)})
    np.testing.assert_allclose(zero.predict_proba(Xt), plain.predict_proba(Xt), atol=1e-10)
    # The other classes' likelihoods are untouched; class 0's adds the source block's own.
    np.testing.assert_allclose(
        zero.log_marginal_likelihood_[1:], plain.log_marginal_likelihood_[1:], rtol=1e-12
    )
    assert zero.log_marginal_likelihood_[0] < plain.log_marginal_likelihood_[0]


def test_related_source_raises_its_class_probability_with_one_observation():
    rng = np.random.default_rng(8)
    centers = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 3.0]])
    X = np.concatenate(
        [
            centers[0] + 0.5 * rng.normal(size=(1, 2)),
            centers[1:].repeat(6, 0) + 0.5 * rng.normal(size=(12, 2)),
        ]
    )
    y = np.array([0] + [1] * 6 + [2] * 6)
    source = centers[0] + 0.5 * rng.normal(size=(20, 2))
    probe = centers[0] + 0.5 * rng.normal(size=(50, 2))
    plain = LaplaceGPC(1.0, 4.0, optimize=False).fit(X, y)
    related = LaplaceGPC(1.0, 4.0, optimize=False).fit(X, y, sources={0: (source, 0.9)})
    assert (
        related.predict_proba(probe)[:, 0].mean() > plain.predict_proba(probe)[:, 0].mean() + 0.05
    )
    assert related.score(probe, np.zeros(50)) >= plain.score(probe, np.zeros(50))


def test_learned_lambda_stays_in_unit_interval():
    X, y = make_blobs(8, 3, 3, seed=9)
    source = make_blobs(10, 1, 3, seed=10)[0]
    model = LaplaceGPC(fixed=(), random_state=0).fit(X, y, sources={2: (source, 0.5)})
    lam = model.theta_[2, -1]
    assert 0.0 <= lam <= 1.0


def test_save_and_load_round_trip(tmp_path):
    X, y = make_blobs(10, 3, 4, seed=11)
    labels = np.array(["a", "b", "c"])[y]
    source = make_blobs(5, 1, 4, seed=12)[0]
    model = LaplaceGPC(modalities={"f": [0, 1], "t": [2, 3]}, random_state=1).fit(
        X, labels, sources={"b": TransferSource(source, transfer_lambda=0.7)}
    )
    path = tmp_path / "model.npz"
    model.save(path)
    with np.load(path, allow_pickle=False) as data:  # no pickled objects inside
        assert "theta" in data.files
    loaded = LaplaceGPC.load(path)
    Xt = np.random.default_rng(0).normal(size=(20, 4))
    np.testing.assert_array_equal(loaded.theta_, model.theta_)
    np.testing.assert_allclose(loaded.predict_proba(Xt), model.predict_proba(Xt), rtol=1e-12)
    np.testing.assert_allclose(
        loaded.log_marginal_likelihood_, model.log_marginal_likelihood_, rtol=1e-12
    )
    assert loaded.get_params()["modalities"] == {"f": [0, 1], "t": [2, 3]}


@pytest.mark.parametrize(
    "y",
    [
        np.arange(12) % 3,
        (np.arange(12) % 2).astype(np.uint8),
        np.arange(12) % 2 == 0,
        np.array(["a", "b", "c"] * 4),
        np.array([7, 7, 7]),
        np.arange(12) % 3 + 0.0,
        np.linspace(0.1, 0.9, 12),
        np.array(["a", 1, 2.5], dtype=object),
        (np.arange(12) % 2).reshape(6, 2),
    ],
)
def test_target_check_agrees_with_scikit_learn(y):
    # fit skips scikit-learn's check for 1-D integer, boolean and string labels (always
    # "binary" or "multiclass"); it must accept and refuse exactly what scikit-learn does.
    try:
        check_classification_targets(y)
    except (ValueError, TypeError) as e:
        with pytest.raises(type(e)):
            fast_check(y)
    else:
        fast_check(y)


def test_continuous_targets_are_still_refused():
    X, _ = make_blobs(10, 2, 3, seed=1)
    with pytest.raises(ValueError, match="Unknown label type"):
        LaplaceGPC(optimize=False).fit(X, np.linspace(0.1, 0.9, len(X)))
