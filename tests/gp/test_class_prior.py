"""The class-prior adjustment of the one-vs-all posterior (``LaplaceGPC(class_prior=...)``)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from aptkt.gp import LaplaceGPC, uniform_class_prior

from .conftest import make_blobs


def bayes_reweighted(binary, counts, totals=None):
    """Reference: each binary posterior re-weighted by Bayes' rule from the training prior
    π_c = n_c / n (positives over all labels of that classifier) to π' = 1 / K (posterior ∝
    likelihood × prior, for y = +1 and y = −1), then normalised over the classes."""
    binary = np.asarray(binary, dtype=float)
    counts = np.asarray(counts, dtype=float)
    k = counts.size
    pi = counts / (counts.sum() if totals is None else np.asarray(totals, dtype=float))
    up = binary * (1 / k) / pi
    down = (1 - binary) * (1 - 1 / k) / (1 - pi)
    adjusted = up / (up + down)
    return adjusted / adjusted.sum(axis=1, keepdims=True)


probabilities = st.floats(1e-6, 1 - 1e-6)


@settings(max_examples=80, deadline=None)
@given(
    data=st.data(),
    k=st.integers(2, 6),
    n_rows=st.integers(1, 5),
)
def test_adjustment_is_bayes_rule_from_training_to_uniform_base_rates(data, k, n_rows):
    binary = data.draw(hnp.arrays(np.float64, (n_rows, k), elements=probabilities))
    counts = np.array(data.draw(st.lists(st.integers(1, 30), min_size=k, max_size=k)))
    out = uniform_class_prior(binary, counts / counts.sum())
    np.testing.assert_allclose(out, bayes_reweighted(binary, counts), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out.sum(axis=1), 1.0, rtol=1e-12)
    # Relabelling the classes relabels the output.
    perm = np.array(data.draw(st.permutations(range(k))))
    np.testing.assert_allclose(
        uniform_class_prior(binary[:, perm], counts[perm] / counts.sum()),
        out[:, perm],
        rtol=1e-9,
        atol=1e-12,
    )


@settings(max_examples=40, deadline=None)
@given(
    binary=hnp.arrays(
        np.float64, st.tuples(st.integers(1, 5), st.integers(2, 6)), elements=probabilities
    ),
    n=st.integers(1, 20),
)
def test_equal_class_counts_leave_the_normalised_posterior_unchanged(binary, n):
    counts = np.full(binary.shape[1], n)
    np.testing.assert_allclose(
        uniform_class_prior(binary, counts / counts.sum()),
        binary / binary.sum(axis=1, keepdims=True),
        rtol=1e-12,
    )


def test_certain_classifiers_stay_certain_and_all_zero_rows_become_uniform():
    out = uniform_class_prior(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]), [5 / 7, 1 / 7, 1 / 7])
    np.testing.assert_array_equal(out, [[1.0, 0.0, 0.0], [1 / 3, 1 / 3, 1 / 3]])
    with pytest.raises(ValueError, match="base_rates"):
        uniform_class_prior(np.full((1, 2), 0.5), [1.0, 0.0])


def test_a_classifier_with_a_source_task_is_moved_from_the_base_rate_it_was_fitted_on():
    # Class 0's classifier also learns from a source task (4 positives, 8 negatives): its
    # labels are 2 + 4 positive of 6 + 12, not 2 of 6, and that is the rate Bayes' rule must
    # move to 1/K. (Counting the new rows alone over-corrects a transferring classifier.)
    from aptkt.gp import TransferSource

    X, y = make_blobs(2, 3, 2, spread=1.0, seed=8)
    Xs, _ = make_blobs(4, 3, 2, spread=1.0, seed=9)
    ys = np.where(np.arange(12) < 4, 1.0, -1.0)
    Xt = np.random.default_rng(3).normal(scale=2, size=(40, 2))
    model = LaplaceGPC(random_state=0, class_prior="uniform").fit(
        X, y, sources={0: TransferSource(Xs, ys, transfer_lambda=0.7)}
    )
    np.testing.assert_allclose(model.base_rates_, [6 / 18, 2 / 6, 2 / 6])
    binary = model.predict_proba_binary(Xt)
    np.testing.assert_allclose(
        model.predict_proba(Xt),
        bayes_reweighted(binary, [6, 2, 2], totals=[18, 6, 6]),
        rtol=1e-9,
    )
    # The unadjusted posterior on request, whatever the setting.
    np.testing.assert_allclose(
        model.predict_proba(Xt, class_prior="training"),
        binary / binary.sum(axis=1, keepdims=True),
        rtol=1e-12,
    )
    with pytest.raises(ValueError, match="class_prior must be one of"):
        model.predict_proba(Xt, class_prior="balanced")


def test_balanced_labels_give_the_same_model_either_way():
    X, y = make_blobs(8, 3, 2, seed=3)
    Xt = np.random.default_rng(1).normal(scale=2, size=(25, 2))
    plain = LaplaceGPC(random_state=0).fit(X, y)
    uniform = LaplaceGPC(random_state=0, class_prior="uniform").fit(X, y)
    np.testing.assert_allclose(uniform.predict_proba(Xt), plain.predict_proba(Xt), atol=1e-15)


@pytest.mark.parametrize("n_classes", [2, 3])
def test_an_over_observed_class_no_longer_wins_by_its_count(n_classes):
    # One class observed four times as often as the others: "training" gives it the
    # ambiguous middle; "uniform" takes its surplus count out, and nothing else changes.
    X, y = make_blobs(12, n_classes, 2, spread=2.0, seed=5)
    keep = (y == 0) | (np.arange(y.size) % 12 < 3)
    X, y = X[keep], y[keep]
    counts = np.bincount(y)
    assert counts[0] == 4 * counts[1]
    Xt = np.random.default_rng(2).normal(scale=3, size=(200, 2))
    plain = LaplaceGPC(random_state=0).fit(X, y)
    uniform = LaplaceGPC(random_state=0, class_prior="uniform").fit(X, y)
    np.testing.assert_array_equal(uniform.theta_, plain.theta_)
    np.testing.assert_array_equal(uniform.predict_proba_binary(Xt), plain.predict_proba_binary(Xt))
    p_plain, p_uniform = plain.predict_proba(Xt), uniform.predict_proba(Xt)
    np.testing.assert_allclose(p_uniform.sum(axis=1), 1.0, rtol=1e-12)
    assert p_uniform[:, 0].mean() < p_plain[:, 0].mean() - 0.05
    assert (uniform.predict(Xt) == 0).sum() < (plain.predict(Xt) == 0).sum()
    np.testing.assert_allclose(
        p_uniform, bayes_reweighted(plain.predict_proba_binary(Xt), counts), rtol=1e-9
    )


def test_bad_class_prior_is_refused_and_the_setting_survives_save_and_load(tmp_path):
    X, y = make_blobs(6, 3, 2, seed=4)
    with pytest.raises(ValueError, match="class_prior must be one of"):
        LaplaceGPC(class_prior="balanced").fit(X, y)
    y = np.r_[y[:6], y[6:12], y[12:14]]
    X = X[: y.size]
    model = LaplaceGPC(random_state=0, class_prior="uniform").fit(X, y)
    model.save(tmp_path / "m.npz")
    loaded = LaplaceGPC.load(tmp_path / "m.npz")
    assert loaded.class_prior == "uniform"
    np.testing.assert_array_equal(loaded.class_counts_, [6, 6, 2])
    np.testing.assert_allclose(loaded.predict_proba(X), model.predict_proba(X), rtol=1e-12)


def test_default_class_prior_is_not_written_so_older_readers_still_load_the_file(tmp_path):
    X, y = make_blobs(6, 3, 2, seed=4)
    for value, written in (("training", False), ("uniform", True)):
        model = LaplaceGPC(random_state=0, class_prior=value).fit(X, y)
        model.save(tmp_path / "m.npz")
        with np.load(tmp_path / "m.npz", allow_pickle=False) as data:
            meta = bytes(data["meta"]).decode()
        assert ('"class_prior"' in meta) is written
        assert LaplaceGPC.load(tmp_path / "m.npz").class_prior == value


def test_an_unknown_class_prior_set_after_fitting_is_refused_at_prediction():
    X, y = make_blobs(6, 3, 2, seed=4)
    model = LaplaceGPC(random_state=0).fit(X, y)
    model.set_params(class_prior="balanced")
    with pytest.raises(ValueError, match="class_prior must be one of"):
        model.predict_proba(X)
