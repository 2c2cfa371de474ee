"""LaplaceGPC as a scikit-learn estimator: scikit-learn's own estimator checks, and the tools
users reach for (score, clone, Pipeline, GridSearchCV, cross_val_score, joblib's n_jobs)."""

import os
import pickle

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.model_selection import GridSearchCV, cross_val_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.estimator_checks import parametrize_with_checks

from aptkt.errors import NotFittedError
from aptkt.gp import DEFAULTS, LaplaceGPC
from aptkt.gp.arguments import threads

from .conftest import make_blobs

# No check needs to be declared as an expected failure (docs/gp.md says so); the ones that need
# pandas or the array API are skipped by scikit-learn itself when those are not installed.
EXPECTED_FAILED_CHECKS: dict[str, str] = {}


@parametrize_with_checks(
    [LaplaceGPC(random_state=0)], expected_failed_checks=lambda est: EXPECTED_FAILED_CHECKS
)
def test_sklearn_estimator_checks(estimator, check):
    check(estimator)


def test_cross_val_score_of_a_pipeline_is_a_number():
    # The reproducer of the report: it returned [nan nan nan] before.
    X, y = make_blobs(15, 3, 4, spread=1.0, seed=0)
    scores = cross_val_score(make_pipeline(StandardScaler(), LaplaceGPC(random_state=0)), X, y)
    assert scores.shape == (5,)
    assert np.all(np.isfinite(scores)) and scores.mean() > 0.8


def test_grid_search_and_score():
    X, y = make_blobs(12, 3, 3, spread=1.0, seed=1)
    search = GridSearchCV(
        LaplaceGPC(random_state=0), {"approximation": ["erf", "quadrature"], "n_restarts": [0, 1]}
    ).fit(X, y)
    assert search.best_params_["n_restarts"] in (0, 1)
    assert 0.8 < search.score(X, y) <= 1.0
    model = LaplaceGPC(random_state=0).fit(X, y)
    assert model.score(X, y) == pytest.approx(np.mean(model.predict(X) == y))


def test_clone_keeps_parameters_not_fit():
    X, y = make_blobs(8, 2, 3, seed=2)
    model = LaplaceGPC(n_restarts=3, hyper_prior="weak", random_state=4).fit(X, y)
    copy = clone(model)
    assert copy.get_params() == model.get_params()
    with pytest.raises(NotFittedError):
        copy.predict(X)


def test_pickle_round_trip_for_joblib():
    X, y = make_blobs(8, 3, 3, seed=3)
    model = LaplaceGPC(random_state=0).fit(X, y, sources={1: (X[:3] + 0.2, 0.5)})
    again = pickle.loads(pickle.dumps(model))
    Xt = np.random.default_rng(0).normal(size=(12, 3))
    np.testing.assert_allclose(again.predict_proba(Xt), model.predict_proba(Xt), rtol=1e-12)
    np.testing.assert_array_equal(again.theta_, model.theta_)


def test_n_jobs_follows_joblib():
    cores = os.cpu_count() or 1
    assert threads(None) == 1
    assert threads(3) == min(3, cores)  # never more than the cores
    assert threads(-1) == cores
    assert threads(-2) == max(1, cores - 1)
    assert threads(-10_000) == 1
    for bad in (0, 1.5, "2", True):
        with pytest.raises(ValueError, match="n_jobs"):
            threads(bad)
    X, y = make_blobs(6, 3, 3, seed=4)
    a = LaplaceGPC(random_state=0, n_jobs=-1).fit(X, y)
    b = LaplaceGPC(random_state=0, n_jobs=None).fit(X, y)
    np.testing.assert_array_equal(a.theta_, b.theta_)  # threads never change the result


def test_learner_settings_take_their_defaults_from_the_gp_layer():
    from aptkt.learning import GPSettings

    settings = GPSettings()
    model = LaplaceGPC()
    for name in ("max_iter", "length_scale", "signal_variance", "approximation"):
        assert getattr(settings, name) == getattr(DEFAULTS, name) == getattr(model, name)
    assert settings.n_jobs == DEFAULTS.n_jobs == model.n_jobs
    # The learner's deliberate departure (MAP-II: one start at the hyper-prior's centre), and
    # the models it makes carry it.
    assert model.n_restarts == DEFAULTS.n_restarts == 1
    assert settings.n_restarts == 0
    assert settings.make({"all": [0, 1]}, random_state=0).n_restarts == 0


def test_plain_arrays_are_validated_as_scikit_learn_validates_them():
    """The fast path for float64 ndarrays (gp.inputs.validate) against scikit-learn's own
    validation, which lists still take: same fit, same fitted
    attributes, the same error for a wrong number of features."""
    X, y = make_blobs(12, 3, 4, spread=1.0, seed=3)
    fast = LaplaceGPC(random_state=0).fit(X, y)
    slow = LaplaceGPC(random_state=0).fit(X.tolist(), y.tolist())
    assert fast.n_features_in_ == slow.n_features_in_ == 4
    assert not hasattr(fast, "feature_names_in_")
    np.testing.assert_array_equal(fast.theta_, slow.theta_)
    np.testing.assert_array_equal(fast.predict_proba(X), slow.predict_proba(X.tolist()))
    np.testing.assert_array_equal(fast.predict_proba(X), fast.predict_proba(np.asfortranarray(X)))
    messages = []
    for wrong in (X[:, :3], X[:, :3].tolist()):
        with pytest.raises(ValueError) as err:
            fast.predict_proba(wrong)
        messages.append(str(err.value))
    assert messages[0] == messages[1]
    assert "X has 3 features, but LaplaceGPC is expecting 4 features as input" in messages[0]
    with pytest.raises(ValueError, match="inconsistent numbers of samples"):
        LaplaceGPC().fit(X, y[:-1])
