"""A library of any size: the identity model's leave-one-out models from its sums against
refits, the impostor table against a direct computation, the local library model against the
exact one (the same within the limits, close beyond them), calibrations computed in parts, and
what a library file carries."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import logsumexp
from sklearn.covariance import ledoit_wolf_shrinkage

from aptkt.errors import PriorFileError
from aptkt.learning import (
    APTKT,
    GPSettings,
    LearnerConfig,
    PoolEnvironment,
    PriorKnowledge,
    locality,
)
from aptkt.learning import identity as identity_module
from aptkt.learning.identity import NEW_OBJECT_PRIOR, ObjectIdentity, _ledoit_wolf
from aptkt.learning.observations import Observations
from aptkt.learning.recognition import calibration_scores


def _library(n_objects: int, n_per: int, d: int, seed: int, spread: float = 3.0):
    rng = np.random.default_rng(seed)
    means = rng.normal(scale=spread, size=(n_objects, d))
    noise = rng.uniform(0.5, 2.0, size=n_objects)
    X = np.concatenate([m + s * rng.normal(size=(n_per, d)) for m, s in zip(means, noise)])
    labels = np.repeat([f"o{k:03d}" for k in range(n_objects)], n_per)
    order = rng.permutation(labels.size)  # rows of one object need not be together
    return X[order], labels[order]


def _observations(n_objects, n_per, seed, prefix="o", action="A", spread=3.0):
    rng = np.random.default_rng(seed)
    means = rng.normal(scale=spread, size=(n_objects, 6))
    X = np.concatenate([m + rng.normal(size=(n_per, 6)) for m in means])
    objects = np.repeat([f"{prefix}{k:03d}" for k in range(n_objects)], n_per)
    trials = np.tile(np.arange(n_per), n_objects)
    return Observations(action, {"a": X[:, :4], "b": X[:, 4:]}, objects, trials)


# -- the identity model from its sums -------------------------------------------------------------
@given(st.integers(0, 10_000), st.integers(2, 6), st.integers(1, 5))
@settings(max_examples=25, deadline=None)
def test_ledoit_wolf_from_sums_is_scikit_learns(seed, d, n_per):
    rng = np.random.default_rng(seed)
    R = rng.normal(size=(n_per * 7, d)) * rng.uniform(0.1, 3.0, size=d)
    sq = (R**2).sum(axis=1)
    ours = _ledoit_wolf(R.T @ R, float((sq**2).sum()), R.shape[0])
    assert ours == pytest.approx(ledoit_wolf_shrinkage(R, assume_centered=True), abs=1e-12)


@given(st.integers(0, 10_000), st.integers(3, 8), st.integers(2, 5))
@settings(max_examples=15, deadline=None)
def test_leaving_one_observation_out_equals_refitting_without_it(seed, n_objects, n_per):
    X, labels = _library(n_objects, n_per, 3, seed)
    model = ObjectIdentity(X, labels)
    rows = np.arange(0, X.shape[0], 3)
    old, new = model.held_in_log_likelihoods(rows)
    for j, r in enumerate(rows):
        keep = np.arange(X.shape[0]) != r
        refit = ObjectIdentity(X[keep], labels[keep])
        ref_old, ref_new = refit.log_likelihoods(X[r][None, :])
        cols = [model.objects_.index(o) for o in refit.objects_]
        np.testing.assert_allclose(old[j, cols], ref_old, rtol=1e-9, atol=1e-9)
        assert new[j] == pytest.approx(ref_new, rel=1e-9, abs=1e-9)
        gone = set(model.objects_) - set(refit.objects_)  # an object seen once: not a candidate
        assert all(old[j, model.objects_.index(o)] == -np.inf for o in gone)


@given(st.integers(0, 10_000), st.integers(3, 8))
@settings(max_examples=15, deadline=None)
def test_leaving_one_object_out_equals_refitting_without_it(seed, n_objects):
    X, labels = _library(n_objects, 4, 3, seed)
    model = ObjectIdentity(X, labels)
    for k, name in enumerate(model.objects_):
        scored = model.held_out_log_likelihoods(k)
        keep = labels != name
        refit = ObjectIdentity(X[keep], labels[keep])
        mine = X[model.rows_of(k)]
        ref = [refit.log_likelihoods(x[None, :]) for x in mine]
        cols = [model.objects_.index(o) for o in refit.objects_]
        np.testing.assert_allclose(scored[0][:, cols], [r[0] for r in ref], rtol=1e-9)
        np.testing.assert_allclose(scored[1], [r[1] for r in ref], rtol=1e-9)
        assert np.all(scored[0][:, k] == -np.inf)


def _impostors_by_refitting(X, labels, n):
    """The impostor odds of the docstring, by refitting the library without each object and
    scoring each set of n consecutive observations against every other object."""
    names = sorted(set(labels.tolist()))
    best = -np.inf
    for o in names:
        keep = labels != o
        rows = X[~keep]
        if rows.shape[0] < n or len(names) - 1 < 2:
            continue
        refit = ObjectIdentity(X[keep], labels[keep])
        for start in range(0, rows.shape[0] - n + 1, n):
            old, new = refit.log_likelihoods(rows[start : start + n])
            joint = np.concatenate(
                [[math.log(NEW_OBJECT_PRIOR) + new], math.log(0.5 / old.size) + old]
            )
            k = 1 + int(np.argmax(joint[1:]))
            best = max(best, joint[k] - logsumexp(np.delete(joint, k)))
    return best


@given(st.integers(0, 10_000), st.integers(3, 7))
@settings(max_examples=10, deadline=None)
def test_the_impostor_table_is_the_largest_odds_of_every_left_out_object(seed, n_objects):
    X, labels = _library(n_objects, 5, 3, seed, spread=1.5)
    # Rows of each object in their given order: the sets are consecutive rows of an object.
    order = np.argsort(labels, kind="stable")
    X, labels = X[order], labels[order]
    model = ObjectIdentity(X, labels)
    for n in (1, 2, 5):
        assert model.impostor_log_odds(n) == pytest.approx(
            _impostors_by_refitting(X, labels, n), rel=1e-8, abs=1e-8
        )
    assert model.impostor_log_odds(6) == -np.inf  # no object has six observations


def test_competitors_beyond_the_nearest_only_raise_the_impostor_odds(monkeypatch):
    """With fewer competitors than objects, each left-out object's odds leave out the farther
    ones' mass: the threshold can only rise (be stricter), and by little."""
    X, labels = _library(30, 4, 3, seed=5, spread=2.0)
    exact = ObjectIdentity(X, labels).impostor_table()
    monkeypatch.setattr(identity_module, "IMPOSTOR_COMPETITORS", 5)
    few = ObjectIdentity(X, labels).impostor_table()
    assert np.all(few[1:] >= exact[1:] - 1e-9)
    assert np.all(few[1:] - exact[1:] < 0.5)


def test_an_impostor_table_in_parts_is_the_table():
    X, labels = _library(12, 4, 3, seed=2)

    def here(fn, items):
        return ((i, fn(item)) for i, item in enumerate(items))

    whole = identity_module.impostor_table(X, labels)
    np.testing.assert_array_equal(identity_module.impostor_table(X, labels, here), whole)


def test_recognition_scores_each_touch_as_the_library_without_it_would():
    X, labels = _library(6, 5, 3, seed=8)
    model = ObjectIdentity(X, labels)
    old, new = model.log_likelihoods_each(X[:4])
    for k in range(4):
        o, n = model.log_likelihoods(X[k][None, :])
        np.testing.assert_allclose(old[k], o, rtol=1e-12)
        assert new[k] == pytest.approx(n, rel=1e-12)


# -- the local library model ------------------------------------------------------------------------
def test_take_objects_keeps_the_limits_and_the_order():
    rows = [np.arange(10 * k, 10 * k + 10) for k in range(30)]
    taken = locality.take_objects([3, 1, 2] + list(range(4, 30)), rows, 4, 35)
    assert taken.tolist() == sorted([*range(30, 40), *range(10, 20), *range(20, 30)])
    # Two objects that exceed the rows alone are thinned evenly.
    thin = locality.take_objects([0, 1], [np.arange(300), np.arange(300, 600)], 16, 400)
    assert thin.size == 400 and thin[0] == 0 and thin[-1] == 599


def test_the_kernel_sample_is_the_library_within_the_limits_and_a_seeded_draw_beyond():
    small = np.repeat([f"o{k}" for k in range(locality.LOCAL_OBJECTS)], 25)
    assert locality.kernel_sample(small, seed=0).size == small.size
    large = np.repeat([f"o{k}" for k in range(200)], 12)
    a, b = locality.kernel_sample(large, seed=0), locality.kernel_sample(large, seed=0)
    assert np.array_equal(a, b) and not np.array_equal(a, locality.kernel_sample(large, seed=1))
    assert a.size <= locality.LOCAL_ROWS
    assert len(set(large[a].tolist())) <= locality.LOCAL_OBJECTS
    # Whole objects: every row of a sampled object.
    for o in set(large[a].tolist()):
        assert np.sum(large[a] == o) == 12


def _run(prior, new_names, pool, test, seed=0, **cfg):
    config = LearnerConfig(budget=6, seed=seed, **cfg)
    env = PoolEnvironment({"A": pool}, seed=seed)
    return APTKT(config, prior).run(env, ["A"], new_names, test={"A": test})


def test_within_the_limits_the_local_model_is_the_exact_one():
    old = _observations(8, 10, seed=1, spread=1.2)
    new = _observations(4, 12, seed=2, prefix="n", spread=1.2)
    pool, test = new.take(np.arange(0, 48, 2)), new.take(np.arange(1, 48, 2))
    names = sorted(set(new.objects.tolist()))
    local = PriorKnowledge.build({"A": old}, seed=0)
    exact = PriorKnowledge.build({"A": old}, gp=GPSettings(library_model="exact"), seed=0)
    assert local["A"].covers_library and local["A"].sample is None
    for aux in (False, True):
        a = _run(local, names, pool, test, auxiliary=aux)
        b = _run(exact, names, pool, test, auxiliary=aux)
        assert [s.mean_accuracy for s in a.steps] == [s.mean_accuracy for s in b.steps]
        assert [s.transfer for s in a.steps] == [s.transfer for s in b.steps]


@pytest.fixture(scope="module")
def forty_exact() -> PriorKnowledge:
    """The exact model of 40 objects × 12 observations, as far apart as real materials are (one
    observation of each tells them apart about as often as on the BioTac set): beyond the local
    model's limits, within the exact model's reach (fitted once; the tests only read it)."""
    return PriorKnowledge.build({"A": _forty()}, gp=GPSettings(library_model="exact"), seed=0)


def _forty() -> Observations:
    return _observations(40, 12, seed=3, spread=2.0)


def test_beyond_the_limits_the_local_model_stays_close_to_the_exact_one(forty_exact):
    """40 objects × 12 observations, as far apart as real materials are (one observation of
    each tells them apart about as often as on the BioTac set): beyond the limits, within the
    exact model's reach. Each candidate's p̄ is within 0.15 of the exact model's (two old objects
    that tie within that may swap places, below ε_neg), Eq. 3 lets the same old object through
    (or none), and the learning curves are alike. (Where objects crowd within the noise — means 1.4 noise levels
    apart — p̄ of new objects like none of the old differs by up to 0.13, 0.19 against 0.11:
    farther objects' negatives are missing from a neighbourhood. It decides nothing there.)"""
    new = _observations(5, 40, seed=4, prefix="n", spread=2.0)
    names = sorted(set(new.objects.tolist()))
    local, exact = PriorKnowledge.build({"A": _forty()}, seed=0), forty_exact
    assert not local["A"].covers_library and exact["A"].covers_library
    X = local["A"].features(new)[0]
    for o in names:
        mine = X[new.objects == o][:3]
        cands = local["A"].candidates(mine)
        assert len(cands) == locality.CANDIDATES
        p_local = local["A"].binary_probabilities(mine, cands).mean(axis=0)
        p_exact = exact["A"].binary_probabilities(mine).mean(axis=0)
        where = [exact["A"].objects.index(c) for c in cands]
        np.testing.assert_allclose(p_local, p_exact[where], atol=0.15)
        # Eq. 3's first cut-off (ε_neg 0.5) lets the same old object through, or none.
        passed = [
            cands[int(np.argmax(p_local))] if p_local.max() >= 0.5 else None,
            exact["A"].objects[int(np.argmax(p_exact))] if p_exact.max() >= 0.5 else None,
        ]
        assert passed[0] == passed[1]
    pool = new.take(np.flatnonzero(new.trials < 10))
    test = new.take(np.flatnonzero(new.trials >= 10))
    curves = [
        np.mean(
            [[s.mean_accuracy for s in _run(p, names, pool, test, seed=k).steps] for k in range(5)],
            axis=0,
        )
        for p in (local, exact)
    ]
    assert np.max(np.abs(curves[0] - curves[1])) < 0.01


def test_near_its_own_observations_an_old_objects_neighbourhood_classifier_is_its_exact_one(
    forty_exact,
):
    """What a neighbourhood leaves out is far from the object: for observations of the object
    itself (a new object that is an old one), its classifier of its neighbourhood gives what
    the classifier of every old observation gives, at the same kernel."""
    local, exact = PriorKnowledge.build({"A": _forty()}, seed=0), forty_exact
    ap = local["A"]
    ap.model = exact["A"].model  # the same kernel: only the neighbourhood differs
    twins = _observations(40, 3, seed=3, spread=2.0)  # the same means, new noise
    X = ap.features(twins)[0]
    for name in ("o003", "o017", "o029"):
        mine = X[twins.objects == name]
        p_local = ap.binary_probabilities(mine, [name])[:, 0]
        p_exact = exact["A"].binary_probabilities(mine, [name])[:, 0]
        np.testing.assert_allclose(p_local, p_exact, atol=0.05)


def test_each_old_objects_neighbourhood_holds_it_and_its_nearest_objects():
    old = _observations(60, 10, seed=6)
    ap = PriorKnowledge.build({"A": old}, seed=0)["A"]
    X = ap.training_features()
    for name in ("o000", "o031"):
        rows = ap.neighbourhood(name)
        held = set(old.objects[rows].tolist())
        assert name in held and len(held) <= locality.LOCAL_OBJECTS
        assert rows.size <= locality.LOCAL_ROWS
        # Its nearest other object by the distance of the means is among them.
        means = {o: X[old.objects == o].mean(axis=0) for o in set(old.objects.tolist())}
        nearest = min(
            (o for o in means if o != name), key=lambda o: np.sum((means[o] - means[name]) ** 2)
        )
        assert nearest in held


# -- what a library file carries --------------------------------------------------------------------
def test_a_saved_library_carries_its_sample_impostors_and_calibration(tmp_path):
    lib = PriorKnowledge.build({"A": _observations(40, 12, seed=7)}, seed=0)
    path = lib.save(tmp_path / "lib.npz")
    back = PriorKnowledge.load(path)
    assert np.array_equal(back["A"].sample, lib["A"].sample)
    assert back["A"].identity.impostors is not None
    np.testing.assert_array_equal(back["A"].identity.impostors, lib["A"].identity.impostors)
    assert back.calibration_scores is not None
    np.testing.assert_array_equal(back.calibration_scores.held_in, lib.scores().held_in)
    touches = _observations(40, 2, seed=7)
    a, b = lib.recognise(touches), back.recognise(touches)
    assert a.predicted == b.predicted and np.allclose(a.novelty, b.novelty)
    assert a.calibration == b.calibration


@pytest.mark.parametrize(
    "member, value, fragment",
    [
        ("a0/sample", np.array([5, 3, 1]), "increasing row numbers"),
        ("a0/impostors", np.full(3, 1.0), "of 13 values"),
        ("a0/impostors", np.full(13, np.nan), "non-finite"),
        ("calibration/held_in", np.array([np.nan]), "NaN"),
        ("calibration/held_out", np.zeros((2, 2)), "1-D float"),
    ],
)
def test_a_damaged_library_part_is_named(tmp_path, member, value, fragment):
    lib = PriorKnowledge.build({"A": _observations(40, 12, seed=7)}, seed=0)
    path = lib.save(tmp_path / "lib.npz")
    with np.load(path, allow_pickle=False) as f:
        arrays = dict(f)
    arrays[member] = value
    bad = tmp_path / "bad.npz"
    np.savez(bad, **arrays)
    with pytest.raises(PriorFileError, match=member.replace("/", ".")) as exc:
        PriorKnowledge.load(bad)
    assert fragment in str(exc.value)


def test_calibration_in_parts_elsewhere_is_the_calibration():
    lib = PriorKnowledge.build({"A": _observations(10, 6, seed=9)}, seed=0)

    def elsewhere(fn, items):  # as a process would: the task pickled, no shared state
        import pickle

        return ((i, fn(pickle.loads(pickle.dumps(item)))) for i, item in enumerate(items))

    here = calibration_scores(lib)
    there = calibration_scores(lib, elsewhere)
    np.testing.assert_allclose(there.held_in, here.held_in, rtol=1e-12)
    np.testing.assert_allclose(there.held_out, here.held_out, rtol=1e-12)


# -- what a library too large for this machine gets -------------------------------------------------
def test_a_library_beyond_this_machines_memory_is_refused_before_its_models_are_fitted(
    monkeypatch,
):
    from aptkt import _core
    from aptkt.errors import ProblemTooLargeError

    monkeypatch.setattr(_core, "available_memory", lambda: 1_000_000)
    fitted = []
    monkeypatch.setattr(GPSettings, "make", lambda *a, **k: fitted.append(a))
    with pytest.raises(ProblemTooLargeError, match=r"40 objects and 480 observations of 6 columns"):
        PriorKnowledge.build({"A": _observations(40, 12, seed=1)})
    assert not fitted


def test_the_exact_model_of_a_large_library_is_refused_naming_the_local_one():
    from aptkt.errors import ProblemTooLargeError

    large = _observations(1000, 12, seed=1)
    with pytest.raises(ProblemTooLargeError, match="use library_model 'local'"):
        PriorKnowledge.build({"A": large}, gp=GPSettings(library_model="exact"))


def test_prior_build_on_a_dask_cluster_gives_the_local_library(tmp_path, capsys):
    """--scheduler: the calibrations are computed on the cluster's workers, and the file is
    the one built here."""
    from dask.distributed import LocalCluster

    from aptkt.cli import main
    from aptkt.learning.feature_table import write_feature_table

    table = write_feature_table(tmp_path / "t.csv", {"A": _observations(30, 8, seed=4)})
    base = ["prior", "build", str(table)]
    assert main([*base, "-j", "1", "-o", str(tmp_path / "here.npz")]) == 0
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        argv = [*base, "--scheduler", cluster.scheduler_address, "-o", str(tmp_path / "there.npz")]
        assert main(argv) == 0
    here, there = (PriorKnowledge.load(tmp_path / f) for f in ("here.npz", "there.npz"))
    np.testing.assert_array_equal(here["A"].identity.impostors, there["A"].identity.impostors)
    np.testing.assert_allclose(there.calibration_scores.held_in, here.calibration_scores.held_in)
    assert "30 objects (o000, o001" in capsys.readouterr().out


def test_prior_build_of_the_exact_model_too_large_is_one_line(tmp_path, capsys):
    from aptkt.cli import main
    from aptkt.learning.feature_table import write_feature_table

    table = write_feature_table(tmp_path / "t.csv", {"A": _observations(1000, 12, seed=4)})
    argv = ["prior", "build", str(table), "--library-model", "exact", "-o", str(tmp_path / "x.npz")]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("aptkt prior build: error: ")
    assert "1000 objects and 12000 observations" in err[0] and "--library-model local" in err[0]
    assert not (tmp_path / "x.npz").exists()


def test_the_method_page_states_the_limits_the_code_has():
    """docs/method.md's "A library of thousands" quotes the limits; they are these constants."""
    from pathlib import Path

    from aptkt.experiments.schedule import LARGEST_BATCH
    from aptkt.learning.identity import IMPOSTOR_COMPETITORS
    from aptkt.learning.recognition import CALIBRATION_OBJECTS, CALIBRATION_TOUCHES

    page = (Path(__file__).parents[2] / "docs" / "method.md").read_text()
    section = " ".join(page.split("## A library of thousands")[1].split("\n## ")[0].split())
    for phrase in (
        f"{locality.LOCAL_OBJECTS} objects and {locality.LOCAL_ROWS} observations",
        f"with its {locality.CANDIDATES} candidates",
        f"its {IMPOSTOR_COMPETITORS} nearest objects",
        f"at most {CALIBRATION_TOUCHES:,} touches and {CALIBRATION_OBJECTS} objects",
        f"from 5 to {LARGEST_BATCH} objects",
    ):
        assert phrase in section, phrase
