"""What carries over from a library that grows: the joint noise metric, the amplitude set by the
task, the length-scale the library proposes and the new labels correct, and the same-object
test that keeps transfers to old objects the new one *is*."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq
from scipy.special import expit
from scipy.stats import multivariate_normal

from aptkt.gp import LaplaceGPC
from aptkt.learning import APTKT, GPSettings, LearnerConfig, PoolEnvironment, PriorKnowledge
from aptkt.learning.config import lone_observation_signal_variance
from aptkt.learning.identity import ObjectIdentity
from aptkt.learning.kernel import data_scale, fit_new_objects, library_evidence
from aptkt.learning.observations import Observations
from aptkt.learning.pipeline import FeaturePipeline, joint_noise_whitener, within_object_residuals

# -- the metric ----------------------------------------------------------------------------------


def _correlated(n_objects=6, n_per=30, seed=0):
    """Two modalities whose noise is correlated across them (one contact moves both)."""
    rng = np.random.default_rng(seed)
    A = np.array([[1.0, 0.0, 0.0], [0.8, 0.6, 0.0], [0.5, 0.3, 0.8]])
    rows, objects = [], []
    for k in range(n_objects):
        mean = rng.normal(scale=5.0, size=3)
        rows.append(mean + rng.normal(size=(n_per, 3)) @ A.T)
        objects += [f"o{k}"] * n_per
    X = np.concatenate(rows)
    obs = Observations("A", {"a": X[:, :1], "b": X[:, 1:]}, np.array(objects))
    return obs, X


def test_joint_whitening_without_shrinkage_leaves_unit_uncorrelated_noise():
    obs, X = _correlated()
    M = joint_noise_whitener(X, obs.objects, shrinkage=0.0)
    R, dof = within_object_residuals(X @ M.T, obs.objects)
    np.testing.assert_allclose(R.T @ R / dof, np.eye(3), atol=1e-10)
    # ZCA: the map is the symmetric root of the inverse correlation, scaled by the noise.
    R0, _ = within_object_residuals(X, obs.objects)
    sd = np.sqrt((R0**2).sum(axis=0) / dof)
    np.testing.assert_allclose(M * sd[None, :], (M * sd[None, :]).T, atol=1e-12)


@given(st.floats(0.0, 1.0), st.integers(0, 10_000))
@settings(max_examples=25, deadline=None)
def test_joint_whitening_removes_the_shrunk_correlation(shrinkage, seed):
    obs, X = _correlated(n_objects=3, n_per=12, seed=seed)
    M = joint_noise_whitener(X, obs.objects, shrinkage=shrinkage)
    R, dof = within_object_residuals(X, obs.objects)
    sd = np.sqrt((R**2).sum(axis=0) / dof)
    corr = (R / sd).T @ (R / sd) / dof
    target = (1 - shrinkage) * corr + shrinkage * np.eye(3)
    # M C Mᵀ = I for the shrunk C (D C_shrunk D), checked without the eigendecomposition.
    shrunk_cov = sd[:, None] * target * sd[None, :]
    np.testing.assert_allclose(M @ shrunk_cov @ M.T, np.eye(3), atol=1e-8)


def test_the_joint_metric_keeps_modality_blocks_and_round_trips(tmp_path):
    obs, _ = _correlated()
    pipe = FeaturePipeline({}).fit(obs, scale="whiten-joint")
    assert pipe.joint_ is not None
    X, groups = pipe.transform(obs)
    assert groups == {"a": [0], "b": [1, 2]}
    R, dof = within_object_residuals(X, obs.objects)
    cov = R.T @ R / dof
    # The shrunk correlation is removed, not the sample's: strongly correlated columns keep a
    # little less than unit noise.
    assert np.all((np.diag(cov) > 0.7) & (np.diag(cov) < 1.05))
    per_modality = FeaturePipeline({}).fit(obs, scale="whiten").transform(obs)[0]
    R2, _ = within_object_residuals(per_modality, obs.objects)
    assert abs(cov[0, 1]) < abs((R2.T @ R2 / dof)[0, 1]) / 2  # cross-modal noise mostly gone
    prior = PriorKnowledge.build({"A": obs}, seed=0)
    path = prior.save(tmp_path / "p.npz")
    again = PriorKnowledge.load(path)
    np.testing.assert_array_equal(again["A"].pipeline.transform(obs)[0], X)


# -- the amplitude -------------------------------------------------------------------------------


@pytest.mark.parametrize("k", [2, 3, 5, 12])
def test_lone_observation_signal_variance_reaches_its_posterior(k):
    """At σ², the Laplace mode of one +1 label alone solves f = σ² (1 − sigmoid(f)); the
    normalised posterior at the observation, its classifier giving p = sigmoid(f) and each other
    1 − p, is the promised 0.9 (closed form, solved independently)."""
    sv = lone_observation_signal_variance(k)
    f = brentq(lambda f: f - sv * (1 - expit(f)), 0.0, 100.0)
    p = expit(f)
    assert p / (p + (k - 1) * (1 - p)) == pytest.approx(0.9, rel=1e-9)
    with pytest.raises(ValueError):
        lone_observation_signal_variance(1)


# -- the length-scale ----------------------------------------------------------------------------


def test_the_library_evidence_is_scikit_learns_summed_per_class_evidence():
    """One modality: the library's curve at a grid length-scale is the sum over one-vs-all
    classes of scikit-learn's Laplace log marginal likelihood at the same fixed kernel."""
    from sklearn.gaussian_process import GaussianProcessClassifier
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel

    rng = np.random.default_rng(2)
    X = np.concatenate([m + rng.normal(size=(6, 3)) for m in rng.normal(scale=3, size=(4, 3))])
    y = np.repeat(["a", "b", "c", "d"], 6)
    curve = library_evidence(X, y, {"m": [0, 1, 2]}, 40.0)
    for k in (2, 9, 15):
        t = curve.log_grid[k]
        kernel = ConstantKernel(40.0, "fixed") * RBF(math.exp(t), "fixed")
        ref = GaussianProcessClassifier(kernel, optimizer=None).fit(X, y)
        total = sum(e.log_marginal_likelihood() for e in ref.base_estimator_.estimators_)
        assert curve.values[k] == pytest.approx(total, rel=1e-6)
        assert curve(t) == pytest.approx(total, rel=1e-6)  # the spline passes through the grid


def test_the_new_objects_length_scale_maximises_every_labels_evidence():
    """The new model's length-scale maximises library + new evidence + hyper-prior: no grid
    point nor nearby length-scale does better (a brute-force check of the search)."""
    rng = np.random.default_rng(5)
    old = rng.normal(scale=4, size=(5, 3))
    X_old = np.concatenate([m + rng.normal(size=(8, 3)) for m in old])
    y_old = np.repeat([f"o{i}" for i in range(5)], 8)
    groups = {"m": [0, 1, 2]}
    curve = library_evidence(X_old, y_old, groups, 30.0)
    X = rng.normal(scale=4, size=(6, 3))
    y = np.array(["n0", "n1", "n2", "n0", "n1", "n2"])
    model = fit_new_objects(X, y, groups, curve)
    assert model.signal_variance_[0] == pytest.approx(30.0)

    def objective(t):
        m = LaplaceGPC(
            length_scale=math.exp(t), signal_variance=30.0, modalities=groups, optimize=False
        )
        return curve(t) + m.fit(X, y).log_marginal_likelihood_.sum() + curve.log_prior(t)

    found = math.log(model.length_scales_[0, 0])
    best = objective(found)
    assert all(best >= objective(t) - 1e-6 for t in curve.log_grid)
    assert best >= objective(found + 0.01) - 1e-6 and best >= objective(found - 0.01) - 1e-6
    assert curve.centre == pytest.approx(
        math.exp(np.mean([math.log(data_scale(X_old, [0, 1, 2]))]))
    )


def test_new_labels_shrink_a_length_scale_the_library_set_too_wide():
    """Old objects 60 noise levels apart favour a wide kernel; new ones 4 apart need a narrow one:
    the new labels pull it in, and the control learns them (a kernel fixed at the library's
    reaches ≈ 0.56 here): where the library's objects lie far apart, its evidence allows a wide
    range of length-scales, and the new labels choose within it."""
    from .test_whitening import _control_accuracy

    assert np.mean([_control_accuracy("whiten-joint", s) for s in range(3)]) > 0.85


# -- the same-object test ------------------------------------------------------------------------


def _library(n_old=6, n_per=20, d=4, seed=0, spread=6.0):
    rng = np.random.default_rng(seed)
    means = rng.normal(scale=spread, size=(n_old, d))
    X = np.concatenate([m + rng.normal(size=(n_per, d)) for m in means])
    objects = np.repeat([f"old{i}" for i in range(n_old)], n_per)
    return means, X, objects


def test_identity_likelihoods_match_an_independent_gaussian_computation():
    means, X, objects = _library()
    model = ObjectIdentity(X, objects)
    V = means[2] + np.random.default_rng(9).normal(size=(3, 4))
    old, new = model.log_likelihoods(V)
    n, d = V.shape
    W = model.within_
    for i, level in enumerate(model.noise_levels_):
        mean_part = multivariate_normal(
            model.means_[i], W * level * (1 / n + 1 / model.counts_[i])
        ).logpdf(V.mean(axis=0))
        # The scatter around V's mean: n − 1 independent N(0, level W) directions' worth.
        D = V - V.mean(axis=0)
        scatter = (
            -0.5 * np.einsum("ij,jk,ik->", D, np.linalg.inv(level * W), D)
            - 0.5 * (n - 1) * (np.linalg.slogdet(2 * np.pi * level * W)[1])
        )
        assert old[i] == pytest.approx(mean_part + scatter, rel=1e-9)
    D = V - V.mean(axis=0)
    scatter_new = (
        -0.5 * np.einsum("ij,jk,ik->", D, np.linalg.inv(W), D)
        - 0.5 * (n - 1) * (np.linalg.slogdet(2 * np.pi * W)[1])
    )
    ref_new = multivariate_normal(model.centre_, model.between_ + W / n).logpdf(V.mean(axis=0))
    assert new == pytest.approx(ref_new + scatter_new, rel=1e-9)


@given(st.integers(0, 1000), st.integers(1, 5))
@settings(max_examples=20, deadline=None)
def test_identity_posterior_is_a_distribution(seed, n):
    means, X, objects = _library(seed=seed)
    model = ObjectIdentity(X, objects)
    V = np.random.default_rng(seed + 1).normal(scale=6.0, size=(n, 4))
    old, new = model.log_posterior(V)
    assert np.exp(old).sum() + np.exp(new) == pytest.approx(1.0, abs=1e-9)
    for i, o in enumerate(model.objects_):
        # log(p / (1 − p)): the mass of every other hypothesis, from the posterior itself.
        others = np.concatenate([[new], np.delete(old, i)])
        expected = old[i] - np.logaddexp.reduce(others)
        assert model.log_odds(V, o) == pytest.approx(expected, rel=1e-6, abs=1e-6)


def test_identity_tells_a_twin_from_a_look_alike_and_more_priors_need_more_evidence():
    means, X, objects = _library(n_old=12)
    model = ObjectIdentity(X, objects)
    rng = np.random.default_rng(3)
    twin = means[5] + rng.normal(size=(3, 4))
    # A look-alike: its mean two noise levels from old5's, in every direction.
    look_alike = means[5] + 2.0 + rng.normal(size=(3, 4))
    assert model.log_odds(twin, "old5") > 3
    assert model.log_odds(look_alike, "old5") < 0
    far = np.full((1, 4), 60.0)
    assert model.log_posterior(far)[1] > math.log(0.99)  # none of them
    # The same twin against a library of 3 of these objects (one of them old5) gets more odds.
    keep = np.isin(objects, ["old1", "old5", "old9"])
    small = ObjectIdentity(X[keep], objects[keep])
    assert small.log_odds(twin, "old5") > model.log_odds(twin, "old5")


def test_transfers_go_to_twins_and_not_to_look_alikes():
    """One action, one 4-column modality, old objects well apart. New objects that are old ones
    under other names get their transfer; new objects 2.5 noise levels from old ones in every
    column do not."""
    rng = np.random.default_rng(0)
    old_means = rng.normal(scale=8.0, size=(8, 4))
    old = [f"old{i}" for i in range(8)]

    def table(spec, n, seed):
        r = np.random.default_rng(seed)
        rows = np.concatenate([m + r.normal(size=(n, 4)) for m in spec.values()])
        objs = np.repeat(list(spec), n)
        return {"A": Observations("A", {"m": rows}, objs)}

    prior = PriorKnowledge.build(table(dict(zip(old, old_means)), 15, 1), seed=0)
    for kind, new_means, expect in (
        ("twins", old_means[:3], True),
        ("look-alikes", old_means[:3] + 2.5, False),
    ):
        news = [f"{kind}{j}" for j in range(3)]
        spec = dict(zip(news, new_means))
        learner = APTKT(LearnerConfig(budget=3, seed=0), prior)
        run = learner.run(PoolEnvironment(table(spec, 8, 2)), ["A"], news, table(spec, 10, 3))
        made = [bool(d.sources) for d in learner.learners["A"].decisions.values()]
        sources = [d.sources for d in learner.learners["A"].decisions.values() if d.sources]
        if expect:
            assert np.mean(made) >= 2 / 3, (kind, made)
            assert all(s[0] == old[news.index(o)] for o, s in zip(news, sources) if s)
        else:
            assert not any(made), (kind, made)
        assert run.steps[-1].mean_accuracy > 0.6


def test_kernel_settings_are_validated():
    assert GPSettings().kernel == "library" and GPSettings().prior_feature_scale == "whiten-joint"
    with pytest.raises(ValueError, match="kernel"):
        GPSettings(kernel="library-ish")
    with pytest.raises(ValueError, match="cutoff"):
        LearnerConfig(cutoff="same")


def test_a_library_holding_look_alikes_asks_for_more_evidence():
    """The cut-off's threshold: at least the log odds the library's own distinct objects give
    each other when each is left out — high where two of them are look-alikes, at the margin
    where they are far apart."""
    rng = np.random.default_rng(1)
    apart = rng.normal(scale=10.0, size=(5, 4))
    alike = apart.copy()
    alike[1] = alike[0] + 0.3  # two distinct objects within a noise level

    def identity(means):
        X = np.concatenate([m + rng.normal(size=(12, 4)) for m in means])
        return ObjectIdentity(X, np.repeat([f"o{i}" for i in range(len(means))], 12))

    assert identity(alike).impostor_log_odds(1) > 3 > identity(apart).impostor_log_odds(1)
    with pytest.raises(ValueError):
        identity(apart).impostor_log_odds(0)


def test_a_far_observation_is_new_even_for_a_library_of_two():
    """Two objects span one direction; a new object off that line is not forced onto them."""
    rng = np.random.default_rng(2)
    X = np.concatenate([m + rng.normal(size=(10, 6)) for m in (np.zeros(6), np.full(6, 5.0))])
    model = ObjectIdentity(X, np.repeat(["a", "b"], 10))
    far = np.array([[0.0, 0.0, 0.0, 30.0, -30.0, 30.0]])
    assert model.log_posterior(far)[1] > math.log(0.99)
    assert model.log_odds(rng.normal(size=(2, 6)), "a") > 3
