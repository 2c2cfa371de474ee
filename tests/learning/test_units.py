"""Hand-computed cases for the pieces of the method."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aptkt.learning import FeaturePipeline, ModalityTransform, Observations, decide_transfer
from aptkt.learning.active import (
    SELECTIONS,
    entropy,
    expected_error_reduction,
    own_error,
    select_next,
    uncertainty,
)
from aptkt.learning.config import EXPLORATION, LearnerConfig
from aptkt.learning.evaluation import accuracy, fused_accuracy
from aptkt.learning.pipeline import MIN_NOISE_DOF, SKIN_TRANSFORMS
from aptkt.learning.transfer import mean_posteriors


def test_mean_posterior_and_lambda():
    # Two observations of new object "n"; old model posteriors over (a, b, c).
    post = np.array([[0.5, 0.3, 0.2], [0.7, 0.1, 0.2]])
    np.testing.assert_allclose(mean_posteriors(post), [0.6, 0.2, 0.2])
    d = decide_transfer("n", ["a", "b", "c"], post, eps_neg=0.4)
    assert d.source == "a" and d.transfer_lambda == pytest.approx(0.6)
    assert d.transfers and d.as_dict()["mean_posterior"] == pytest.approx(
        {"a": 0.6, "b": 0.2, "c": 0.2}
    )


def test_eps_neg_cut_off():
    post = np.array([[0.38, 0.32, 0.30]])
    assert decide_transfer("n", ["a", "b", "c"], post, eps_neg=0.4).source is None
    assert decide_transfer("n", ["a", "b", "c"], post, eps_neg=0.4).transfer_lambda == 0.0
    at_threshold = decide_transfer("n", ["a", "b", "c"], np.array([[0.4, 0.3, 0.3]]), eps_neg=0.4)
    assert at_threshold.source == "a"  # Eq. 3 transfers when p̄ >= ε_neg
    assert decide_transfer("n", ["a", "b", "c"], post, eps_neg=0.0, mode="none").source is None
    with pytest.raises(ValueError):
        decide_transfer("n", ["a", "b"], post, eps_neg=0.4)


def test_entropy_and_uncertainty():
    p = np.array([[1.0, 0.0], [0.5, 0.5], [0.25, 0.75]])
    h = entropy(p)
    np.testing.assert_allclose(h, [0.0, np.log(2), -(0.25 * np.log(0.25) + 0.75 * np.log(0.75))])
    assert uncertainty(p) == pytest.approx(h.mean())


def test_selection_argmax_and_ties():
    unc = {("P1", "x"): 0.2, ("P1", "y"): 0.9, ("S1", "x"): 0.9, ("S1", "y"): 0.1}
    rng = np.random.default_rng(0)
    sel = select_next(unc, ["P1", "S1"], ["x", "y"], eps_explor=0.0, rng=rng)
    assert (sel.action, sel.object, sel.explored) == ("P1", "y", False)  # first of the tied maxima
    sel = select_next(
        unc, ["P1", "S1"], ["x", "y"], eps_explor=0.0, rng=rng, available=[("S1", "x"), ("S1", "y")]
    )
    assert (sel.action, sel.object) == ("S1", "x")


def test_own_error_is_the_posterior_mass_on_the_other_objects():
    p = np.array([[0.7, 0.2, 0.1], [0.5, 0.5, 0.0]])
    assert own_error(p, 0) == pytest.approx(1 - 0.6)
    assert own_error(p, 1) == pytest.approx(1 - 0.35)
    with pytest.raises(ValueError):
        own_error(p, 3)
    with pytest.raises(ValueError):
        own_error(np.zeros((0, 3)), 0)


@given(
    st.floats(0.0, 1.0),
    st.integers(1, 10_000),
)
def test_the_error_one_touch_removes_follows_an_error_falling_as_one_over_n(error, count):
    """With error e after n touches and error ∝ 1/n, one more touch leaves e·n/(n + 1): it
    removes e − e·n/(n + 1); a pair's score falls with every touch of it, so none starves."""
    removed = expected_error_reduction(error, count)
    assert removed == pytest.approx(error - error * count / (count + 1), abs=1e-12)
    assert expected_error_reduction(error, count + 1) <= removed
    with pytest.raises(ValueError):
        expected_error_reduction(error, 0)


def test_each_rule_has_its_own_exploration_unless_one_is_given():
    assert set(EXPLORATION) == set(SELECTIONS)
    assert LearnerConfig().selection == "error-reduction" and LearnerConfig().exploration == 0.0
    assert LearnerConfig.paper().selection == "paper" and LearnerConfig.paper().exploration == 0.1
    assert LearnerConfig(selection="random", eps_explor=0.0).exploration == 1.0
    assert LearnerConfig(eps_explor=0.25).exploration == 0.25
    with pytest.raises(ValueError, match="selection"):
        LearnerConfig(selection="greedy")
    # A configuration written before the rule existed reads back with today's default.
    old = LearnerConfig.paper().to_dict()
    del old["selection"]
    assert LearnerConfig.from_dict(old).selection == "error-reduction"


def test_exploration_is_uniform_over_pairs():
    unc = {("P1", "x"): 0.0, ("P1", "y"): 1.0, ("S1", "x"): 0.0, ("S1", "y"): 0.0}
    rng = np.random.default_rng(1)
    picks = [select_next(unc, ["P1", "S1"], ["x", "y"], 1.0, rng) for _ in range(4000)]
    assert all(p.explored for p in picks)
    counts = {}
    for p in picks:
        counts[(p.action, p.object)] = counts.get((p.action, p.object), 0) + 1
    assert set(counts) == set(unc)
    assert all(abs(c / 4000 - 0.25) < 0.03 for c in counts.values())
    # With ε = 0.3 about 30 % of picks explore.
    rng = np.random.default_rng(2)
    frac = np.mean(
        [select_next(unc, ["P1", "S1"], ["x", "y"], 0.3, rng).explored for _ in range(4000)]
    )
    assert abs(frac - 0.3) < 0.03


def test_pca_is_fitted_on_training_observations_only():
    rng = np.random.default_rng(0)
    train = Observations(
        "C1", {"thermal": rng.normal(size=(30, 40))}, np.repeat(["a", "b", "c"], 10)
    )
    test = Observations(
        "C1", {"thermal": rng.normal(size=(20, 40)) * 50 + 9}, np.repeat(["a", "b"], 10)
    )
    pipe = FeaturePipeline({"thermal": ModalityTransform(pca_components=10)}).fit(train)
    t = pipe.transforms["thermal"]
    np.testing.assert_allclose(t.mean_, train.modalities["thermal"].mean(axis=0))
    before = (t.mean_.copy(), t.components_.copy())
    X_test, groups = pipe.transform(test)
    assert X_test.shape == (20, 10) and groups == {"thermal": list(range(10))}
    np.testing.assert_array_equal(t.mean_, before[0])  # transforming test data changes nothing
    np.testing.assert_array_equal(t.components_, before[1])
    # The scores of the training data are uncorrelated (PCA on the training data).
    X_train, _ = pipe.transform(train)
    cov = np.cov(X_train.T)
    assert np.max(np.abs(cov - np.diag(np.diag(cov)))) < 1e-10


def test_pca_keeps_at_most_rank_components():
    obs = Observations(
        "C1", {"thermal": np.random.default_rng(1).normal(size=(4, 40))}, ["a", "b", "c", "d"]
    )
    pipe = FeaturePipeline(SKIN_TRANSFORMS).fit(obs)
    assert pipe.transform(obs)[0].shape == (4, 3)


def test_log_columns_and_constant_columns():
    X = np.array([[1e-4, 1.0, 5.0], [1e-2, 2.0, 5.0], [1e-3, 3.0, 5.0]])
    obs = Observations("S1", {"texture": X}, ["a", "b", "c"])
    pipe = FeaturePipeline({"texture": ModalityTransform(log_columns=(0,))}).fit(obs)
    Z, _ = pipe.transform(obs)
    np.testing.assert_allclose(Z[:, 0], (np.array([-4, -2, -3]) + 3) / np.std([-4, -2, -3]))
    np.testing.assert_allclose(Z[:, 2], 0.0)  # constant column: centred, not divided by zero


def test_observations_reject_nan_with_location():
    with pytest.raises(
        ValueError, match=r"modality 'force': non-finite value nan in observation 1 \(object 'b'\)"
    ):
        Observations("P1", {"force": [[1.0], [np.nan]]}, ["a", "b"])
    with pytest.raises(ValueError, match="expected shape"):
        Observations("P1", {"force": np.zeros((3, 1))}, ["a", "b"])


def test_accuracy_and_fusion():
    classes = ["a", "b"]
    pa = np.array([[0.9, 0.1], [0.4, 0.6], [0.45, 0.55]])
    assert accuracy(pa, classes, ["a", "b", "a"]) == pytest.approx(2 / 3)
    # Two actions; the third sample is wrong under action A alone but right when fused.
    pb = np.array([[0.6, 0.4], [0.3, 0.7], [0.8, 0.2]])
    truth = {"A": np.array(["a", "b", "a"]), "B": np.array(["a", "b", "a"])}
    assert fused_accuracy({"A": pa, "B": pb}, truth, classes) == 1.0


def test_a_column_constant_to_its_last_bits_is_not_blown_up():
    """A column constant up to rounding (1e5 ± one ulp) keeps scale 1: a tiny change of a test
    value stays tiny instead of becoming a z-score of 1e8."""
    X = np.full((6, 2), 1e5)
    X[:, 1] = np.arange(6.0)
    X[:, 0] += np.array([0, 1, 0, 1, 0, 1]) * np.spacing(1e5)
    t = ModalityTransform().fit(X)
    assert t.scale_[0] == 1.0 and t.scale_[1] == pytest.approx(np.arange(6.0).std())
    z = t.transform(X[:1] + [0.001, 0.0])
    assert abs(z[0, 0]) < 0.01


@settings(max_examples=60, deadline=None)
@given(
    sizes=st.lists(st.integers(1, 8), min_size=2, max_size=5),
    seed=st.integers(0, 10_000),
    shifts=st.lists(st.floats(-1e3, 1e3), min_size=5, max_size=5),
)
def test_noise_scale_is_the_pooled_within_object_sd(sizes, seed, shifts):
    """scale="noise" divides by the residual SD of a one-way layout (least squares on object
    indicators, an independent computation), which no shift of an object's observations moves."""
    rng = np.random.default_rng(seed)
    objects = np.repeat([f"o{i}" for i in range(len(sizes))], sizes)
    X = rng.normal(size=(objects.size, 3)) * [1.0, 10.0, 0.1]
    if objects.size - len(sizes) < max(MIN_NOISE_DOF, len(sizes)):
        # Too few repeats to estimate a noise from: the spread, as without objects.
        t = ModalityTransform().fit(X, objects=objects)
        assert np.allclose(t.scale_, X.std(axis=0))
        return
    dummies = (objects[:, None] == np.unique(objects)[None, :]).astype(float)
    residual = X - dummies @ np.linalg.lstsq(dummies, X, rcond=None)[0]
    expected = np.sqrt((residual**2).sum(axis=0) / (objects.size - len(sizes)))
    t = ModalityTransform().fit(X, objects=objects)
    assert np.allclose(t.scale_, expected, rtol=1e-9)
    shifted = X + dummies @ np.array(shifts[: len(sizes)])[:, None]
    assert np.allclose(
        ModalityTransform().fit(shifted, objects=objects).scale_, expected, rtol=1e-6
    )


def test_noise_scaled_pipeline_measures_distances_in_noise_units():
    rng = np.random.default_rng(3)
    objects = np.repeat(["a", "b", "c"], 20)
    # Column 0: objects far apart, little noise; column 1: objects alike, much noise. Scaled by
    # the spread both columns look alike; scaled by the noise, column 0 carries the objects.
    X = np.column_stack(
        [np.repeat([0.0, 5.0, 10.0], 20) + 0.1 * rng.normal(size=60), 3.0 * rng.normal(size=60)]
    )
    obs = Observations("P1", {"force": X}, objects)
    spread, _ = FeaturePipeline().fit(obs).transform(obs)
    noise, _ = FeaturePipeline().fit(obs, scale="whiten").transform(obs)
    assert spread[:, 0].std() == pytest.approx(1.0) and spread[:, 1].std() == pytest.approx(1.0)
    assert noise[:, 0].std() > 30 * noise[:, 1].std()
    with pytest.raises(ValueError, match="scale must be one of"):
        FeaturePipeline().fit(obs, scale="total")
    # A column that differs between objects but never within one has no noise: it keeps its
    # spread (not a raw-unit scale of 1), and a constant column still gets 1.
    per_object = np.column_stack([np.repeat([0.0, 500.0, 1000.0], 20), X[:, 1], np.full(60, 7.0)])
    t = ModalityTransform().fit(per_object, objects=objects)
    assert t.scale_[0] == pytest.approx(per_object[:, 0].std())
    assert t.scale_[2] == 1.0
