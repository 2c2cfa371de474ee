"""APTKTClassifier: scikit-learn's estimator checks for the baseline, a Gaussian-process classifier
as the baseline's reference, the one-shot gain of a related library, the learner's own model
at its first step, libraries built from arrays and read back from their files, and the
mistakes it names."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.gaussian_process import GaussianProcessClassifier
from sklearn.model_selection import cross_val_score
from sklearn.utils.estimator_checks import parametrize_with_checks

from aptkt.errors import (
    InvalidInputError,
    InvalidTypeError,
    NotFittedError,
    UnknownNameError,
)
from aptkt.learning import (
    APTKT,
    APTKTClassifier,
    LearnerConfig,
    Observations,
    PoolEnvironment,
    PriorKnowledge,
)

# None: the baseline passes every check that applies (the array API check is skipped by
# scikit-learn itself without SCIPY_ARRAY_API). With a library the columns are the library's,
# so checks that fit arrays of their own widths do not apply; the tests below cover it.
EXPECTED_FAILED_CHECKS: dict[str, str] = {}


@parametrize_with_checks(
    [APTKTClassifier(random_state=0)], expected_failed_checks=lambda est: EXPECTED_FAILED_CHECKS
)
def test_sklearn_estimator_checks(estimator, check):
    check(estimator)


def _blobs(n, centres, sd, seed):
    rng = np.random.default_rng(seed)
    labels = np.repeat(np.arange(len(centres)), n)
    return np.asarray(centres, dtype=float)[labels] + sd * rng.normal(size=(labels.size, 2)), labels


def test_without_a_library_it_learns_as_a_gaussian_process_classifier():
    """The baseline is a GP classifier (each class's own kernel, Laplace): on separable blobs
    its held-out accuracy is scikit-learn's GaussianProcessClassifier's, within a few rows."""
    centres = [[0.0, 0.0], [4.0, 0.0], [2.0, 3.5]]
    X, y = _blobs(15, centres, 1.2, seed=0)
    Xt, yt = _blobs(60, centres, 1.2, seed=1)
    ours = APTKTClassifier(random_state=0).fit(X, y)
    theirs = GaussianProcessClassifier(random_state=0).fit(X, y)
    assert ours.feature_space_ == "new" and ours.transfer_ == {}
    assert ours.score(Xt, yt) > 0.85 and theirs.score(Xt, yt) > 0.85
    assert abs(ours.score(Xt, yt) - theirs.score(Xt, yt)) <= 0.05
    proba = ours.predict_proba(Xt)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)
    # The classes' columns follow classes_, whatever the model's own (text) order.
    labels = np.array([10, 2, 33])[y]
    relabelled = APTKTClassifier(random_state=0).fit(X, labels)
    np.testing.assert_array_equal(relabelled.classes_, [2, 10, 33])
    np.testing.assert_array_equal(relabelled.predict(Xt), np.array([10, 2, 33])[ours.predict(Xt)])


def test_column_groups_without_a_library_are_the_model_s_modalities():
    X, y = _blobs(6, [[0.0, 0.0], [3.0, 3.0]], 0.5, seed=2)
    est = APTKTClassifier(modalities={"force": [0], "heat": [1]}).fit(X, y)
    assert est.modalities_ == {"force": [0], "heat": [1]}
    assert list(est.model_.modality_names_) == ["force", "heat"]
    for wrong, error in (
        ({"force": [0], "heat": [0, 1]}, "two modalities"),
        ({"force": [2]}, "not one of X's 2 columns"),
        ({"force": []}, "no columns"),
    ):
        with pytest.raises(InvalidInputError, match=error):
            APTKTClassifier(modalities=wrong).fit(X, y)
    with pytest.raises(InvalidTypeError, match="modalities"):
        APTKTClassifier(modalities=[[0], [1]]).fit(X, y)


# -- a library of materials, some of which come back under new names ------------------------
SIGNAL, NOISE = 2, 4  # columns that tell the objects apart; columns of pure, large noise
SD = np.r_[np.full(SIGNAL, 0.7), np.full(NOISE, 4.0)]


def _world(seed, n_objects=4):
    rng = np.random.default_rng(seed)
    means = np.c_[rng.normal(scale=3.0, size=(n_objects, SIGNAL)), np.zeros((n_objects, NOISE))]

    def draw(n):
        labels = np.repeat(np.arange(n_objects), n)
        return means[labels] + SD * rng.normal(size=(labels.size, SIGNAL + NOISE)), labels

    return draw


def _library(X, labels, seed=0):
    names = np.array([f"old{k}" for k in labels])
    return PriorKnowledge.build({"press": Observations.from_arrays("press", names, f=X)}, seed=seed)


def test_a_related_library_beats_the_baseline_at_one_observation_per_object():
    """The new objects are the library's materials under new names, one observation each: the
    library knows which columns are noise and which old object each new one is, the baseline
    has four rows to learn from. Its transfers pair each new object with its own material."""
    gains, transferred = [], 0
    for seed in range(3):
        draw = _world(seed)
        library = _library(*draw(10))
        X, y = draw(1)
        Xt, yt = draw(20)
        with_prior = APTKTClassifier(library, random_state=0).fit(X, y)
        baseline = APTKTClassifier(random_state=0).fit(X, y)
        gains.append(with_prior.score(Xt, yt) - baseline.score(Xt, yt))
        assert with_prior.feature_space_ == "prior" and set(with_prior.transfer_) == {0, 1, 2, 3}
        for label, decision in with_prior.transfer_.items():
            if decision.transfers:
                transferred += 1
                assert decision.source == f"old{label}"
                assert 0.5 <= decision.transfer_lambda <= 1.0
    assert np.mean(gains) > 0.25, gains
    assert transferred > 0


def test_the_estimator_fits_what_the_learner_fits_at_its_first_step():
    """The same rows as the learner's initial round give the same model: the estimator is the
    learner's per-action fit, not a second implementation of it."""
    draw = _world(5)
    library = _library(*draw(10))
    names = np.array([f"new{k}" for k in range(4)])

    def table(n):
        X, labels = draw(n)
        return {"press": Observations.from_arrays("press", names[labels], f=X)}

    pool, test = table(1), table(10)
    learner = APTKT(LearnerConfig(budget=0, seed=3), library)
    learner.run(PoolEnvironment(pool, seed=0), ["press"], list(names), test=test)
    fitted = learner.learners["press"]
    est = APTKTClassifier(library, random_state=3).fit(
        fitted.observations.modalities["f"], fitted.observations.objects
    )
    np.testing.assert_allclose(
        est.predict_proba(test["press"].modalities["f"]), fitted.test_posteriors, atol=1e-10
    )
    assert {c: d.source for c, d in est.transfer_.items()} == {
        c: d.source for c, d in fitted.decisions.items()
    }


def _wheel_library():
    """A library from plain arrays, as tests/packaging/test_wheel.py's run builds one."""
    rng = np.random.default_rng(0)
    centres = {"old_a": 0.0, "old_b": 4.0, "new_a": 0.5, "new_b": 4.5}

    def table(objects, n):
        objs = np.repeat(objects, n)
        force = np.array([[centres[o] + rng.normal()] for o in objs])
        heat = np.array([[-centres[o] + rng.normal(), rng.normal()] for o in objs])
        return Observations.from_arrays("press", objs, force=force, heat=heat)

    library = PriorKnowledge.build({"press": table(["old_a", "old_b"], 8)}, seed=0)
    new = table(["new_a", "new_b"], 3)
    X = np.hstack([new.modalities["force"], new.modalities["heat"]])
    return library, X, new.objects


def test_a_library_built_from_arrays_and_read_back_from_its_file(tmp_path):
    library, X, y = _wheel_library()
    est = APTKTClassifier(library, transfer="paper", random_state=0).fit(X, y)
    proba = est.predict_proba(X)
    assert proba.shape == (6, 2) and np.allclose(proba.sum(axis=1), 1.0)
    assert est.score(X, y) == 1.0
    assert est.action_ == "press" and est.n_features_in_ == 3
    assert est.modalities_ == {"force": [0], "heat": [1, 2]}
    loaded = PriorKnowledge.load(library.save(tmp_path / "library.npz"))
    again = APTKTClassifier(loaded, transfer="paper", random_state=0).fit(X, y)
    np.testing.assert_allclose(again.predict_proba(X), proba, rtol=1e-6, atol=1e-9)
    assert {c: d.source for c, d in again.transfer_.items()} == {
        c: d.source for c, d in est.transfer_.items()
    }


def test_scikit_learn_s_tools_work_with_a_library():
    library, X, y = _wheel_library()
    est = APTKTClassifier(library, random_state=0)
    assert est.get_params()["prior"] is library
    twin = clone(est)
    assert twin.prior is library  # shared, not copied: a library is only read
    assert twin.set_params(transfer="control").transfer == "control"
    assert cross_val_score(est, X, y, cv=3).mean() >= 0.5
    fitted = est.fit(X, y)
    back = pickle.loads(pickle.dumps(fitted))
    np.testing.assert_allclose(back.predict_proba(X), fitted.predict_proba(X))
    assert "PriorKnowledge(2 objects" in repr(est)
    control = APTKTClassifier(library, transfer="control").fit(X, y)
    assert control.transfer_ == {} and control.feature_space_ == "prior"
    baseline = APTKTClassifier(library, transfer="none").fit(X, y)
    assert baseline.feature_space_ == "new"


def test_a_library_of_several_actions_needs_the_action():
    rng = np.random.default_rng(3)
    objects = np.repeat(["a", "b"], 5)
    table = {
        "press": Observations.from_arrays("press", objects, f=rng.normal(size=(10, 2))),
        "slide": Observations.from_arrays("slide", objects, g=rng.normal(size=(10, 3))),
    }
    library = PriorKnowledge.build(table, seed=0)
    X, y = rng.normal(size=(4, 3)), np.array([0, 0, 1, 1])
    with pytest.raises(InvalidInputError, match="several actions .*action="):
        APTKTClassifier(library).fit(X, y)
    with pytest.raises(UnknownNameError, match="no action 'poke'"):
        APTKTClassifier(library, action="poke").fit(X, y)
    with pytest.raises(InvalidInputError, match="X has 3 columns, but .*'press' has 2"):
        APTKTClassifier(library, action="press").fit(X, y)
    est = APTKTClassifier(library, action="slide").fit(X, y)
    assert est.action_ == "slide" and est.n_features_in_ == 3


def test_mistakes_are_named_with_typed_errors():
    library, X, y = _wheel_library()
    with pytest.raises(NotFittedError):
        APTKTClassifier(library).predict(X)
    bad = X.copy()
    bad[2, 1] = np.nan
    with pytest.raises(InvalidInputError, match="NaN in row 2, column 1"):
        APTKTClassifier(library).fit(bad, y)
    est = APTKTClassifier(library).fit(X, y)
    bad[2, 1] = np.inf
    with pytest.raises(InvalidInputError, match="inf in row 2, column 1"):
        est.predict(bad)
    with pytest.raises(InvalidInputError, match="X has 2 features, but APTKTClassifier"):
        est.predict(X[:, :2])
    with pytest.raises(
        InvalidInputError, match="X has 2 columns, but .*force \\(1\\), heat \\(2\\)"
    ):
        APTKTClassifier(library).fit(X[:, :2], y)
    with pytest.raises(InvalidInputError, match="one class"):
        APTKTClassifier(library).fit(X, np.full(len(X), "new_a"))
    with pytest.raises(InvalidInputError, match="leave modalities=None"):
        APTKTClassifier(library, modalities={"f": [0, 1, 2]}).fit(X, y)
    with pytest.raises(InvalidTypeError, match="prior must be a PriorKnowledge"):
        APTKTClassifier("library.npz").fit(X, y)
    for prior in (library, None):
        with pytest.raises(InvalidInputError, match="transfer must be one of"):
            APTKTClassifier(prior, transfer="most").fit(X, y)
    with pytest.raises(InvalidInputError, match="auxiliary .*prior="):
        APTKTClassifier(auxiliary=True).fit(X, y)
    with pytest.raises(InvalidInputError, match="Unknown label type"):
        APTKTClassifier().fit(X[:4], np.array([0.5, 1.25, 2.0, 3.5]))
