"""``LearnerConfig(feature_space="evidence")``: the model is fitted in the prior's feature space
and in the new objects' own, and the space under which the new labels are more probable is kept
(issue 11). The evidence against an independent Laplace computation, the choice on two
constructed worlds, and what happens when a candidate gives no number."""

import numpy as np
import pytest

from aptkt.errors import KernelNotPositiveDefiniteError
from aptkt.experiments.runs import step_rows
from aptkt.gp import LaplaceGPC, TransferSource
from aptkt.learning import (
    APTKT,
    GPSettings,
    LearnerConfig,
    PoolEnvironment,
    PriorKnowledge,
)
from aptkt.learning.evidence import coupling_evidence, label_evidence, target_evidence
from aptkt.learning.learner import ActionLearner, choose_space

from .synthetic import SHAPE_ACTION as ACTION
from .synthetic import SHAPE_NEW as NEW
from .synthetic import SHAPE_OLD as OLD
from .synthetic import shape_table as _table
from .test_transfer_options import _laplace_log_evidence


# -- the evidence, against an independent Laplace computation -----------------------------------
def _rbf(hp, names, modalities):
    def k(A, B):
        out = 0.0
        for m, cols in zip(names, modalities):
            d2 = ((A[:, None, cols] - B[None, :, cols]) ** 2).sum(-1)
            out = out + hp["modality_weights"][m] * np.exp(-d2 / (2 * hp["length_scales"][m] ** 2))
        return hp["signal_variance"] * out

    return k


def test_label_evidence_is_each_classifiers_labels_given_its_source():
    """Σ over the one-vs-all classifiers of log p(y_k | y_source) = log Z(joint) − log Z(source
    alone) for a classifier with a source task, log Z(y_k) for one without, at each
    classifier's fitted hyper-parameters — against a Laplace computation written out in numpy."""
    rng = np.random.default_rng(3)
    centres = rng.normal(scale=2.0, size=(3, 3))
    X = np.concatenate([c + 0.7 * rng.normal(size=(3, 3)) for c in centres])
    y = np.repeat(["a", "b", "c"], 3)
    X_src = np.concatenate([centres[0] + 0.7 * rng.normal(size=(6, 3)), rng.normal(size=(6, 3))])
    y_src = np.repeat([1.0, -1.0], 6)
    groups = {"one": [0, 1], "two": [2]}
    model = LaplaceGPC(modalities=groups, hyper_prior="weak", random_state=0).fit(
        X, y, sources={"a": TransferSource(X_src, y_src, transfer_lambda=0.7)}
    )
    names, mods = list(model.modality_names_), list(model.modalities_)
    total = 0.0
    for k, c in enumerate(model.classes_):
        hp = model.hyperparameters_[c]
        rbf = _rbf(hp, names, mods)
        yk = np.where(y == c, 1.0, -1.0)
        target = _laplace_log_evidence(rbf(X, X), yk)
        assert target_evidence(model, k) == pytest.approx(target, abs=1e-6)
        if c != "a":
            total += target
            continue
        lam = 0.7
        K = np.block([[rbf(X_src, X_src), lam * rbf(X_src, X)], [lam * rbf(X, X_src), rbf(X, X)]])
        joint = _laplace_log_evidence(K, np.concatenate([y_src, yk]))
        source = _laplace_log_evidence(rbf(X_src, X_src), y_src)
        assert coupling_evidence(model, k) == pytest.approx(joint - source - target, abs=1e-6)
        total += joint - source
    assert label_evidence(model) == pytest.approx(total, abs=1e-5)
    # Without sources and with two classes one classifier serves both: counted once.
    two = LaplaceGPC(modalities=groups, random_state=0).fit(X[:6], y[:6])
    hp = two.hyperparameters_["b"]
    expected = _laplace_log_evidence(
        _rbf(hp, names, mods)(X[:6], X[:6]), np.where(y[:6] == "b", 1.0, -1.0)
    )
    assert label_evidence(two) == pytest.approx(expected, abs=1e-6)
    with pytest.raises(ValueError, match="exactly one"):
        coupling_evidence(model, 1)  # class "b" has no source


def test_the_target_evidence_with_a_source_needs_the_zero_mean():
    """With the base-rate latent mean the coupled model's mean comes from source and target
    labels together; the target's evidence alone at that mean is not what a target-only fit
    gives, so it is refused rather than computed wrongly."""
    rng = np.random.default_rng(1)
    X, y = rng.normal(size=(8, 2)), np.repeat(["a", "b"], 4)
    src = TransferSource(rng.normal(size=(10, 2)), np.repeat([1.0, -1.0], 5), transfer_lambda=0.6)
    model = LaplaceGPC(latent_mean="base-rate", random_state=0).fit(X, y, sources={"a": src})
    k = list(model.classes_).index("a")
    with pytest.raises(ValueError, match="latent_mean"):
        target_evidence(model, k)
    with pytest.raises(ValueError, match="latent_mean"):
        label_evidence(model)


def test_several_sources_are_refused():
    rng = np.random.default_rng(0)
    X, y = rng.normal(size=(6, 2)), np.repeat(["a", "b"], 3)
    model = LaplaceGPC(random_state=0).fit(
        X, y, sources={"a": [(rng.normal(size=(4, 2)), 0.5), (rng.normal(size=(4, 2)), 0.4)]}
    )
    with pytest.raises(ValueError, match="exactly one"):
        label_evidence(model)
    with pytest.raises(ValueError, match="multi"):
        LearnerConfig(transfer="multi", feature_space="evidence")
    cfg = LearnerConfig(feature_space="evidence")
    assert LearnerConfig.from_dict(cfg.to_dict()) == cfg


# -- the choice on constructed worlds -------------------------------------------------------------
def _learn(old, new, budget=3, **cfg):
    # The worlds below are built around the prior's space scaled by the old objects' spread
    # (what the evidence must see through); the noise scale would remove part of the contrast.
    prior = PriorKnowledge.build(
        _table(old, 12, seed=1), gp=GPSettings(prior_feature_scale="spread"), seed=0
    )
    config = LearnerConfig(
        **{"budget": budget, "seed": 1, "cutoff": "paper", "eps_neg": 0.0, **cfg}
    )
    learner = APTKT(config, prior)
    run = learner.run(
        PoolEnvironment(_table(new, 10, seed=2), seed=1), [ACTION], NEW, _table(new, 6, seed=3)
    )
    return learner, run


# The old objects spread widely along column 0 and hardly vary in column 1. The new objects lie
# far beyond all of them (like none of the old ones), a few units apart along column 0 and with
# unit noise in column 1: the prior's scaling squeezes their differences (÷ ~65) and blows their
# noise up (÷ 0.01), so in the prior's space they cannot be told apart.
BEYOND_OLD = {o: ([c, 0.0], [1.0, 0.01]) for o, c in zip(OLD, (-80.0, 0.0, 80.0))}
BEYOND_NEW = {o: ([1000.0 + c, 0.0], [0.5, 1.0]) for o, c in zip(NEW, (0.0, 3.0, 6.0))}
# Each new object inside an old object's cluster; column 1 is noise that the old objects spread
# over widely (the prior's scaling shrinks it) and the few new observations hardly (their own
# scaling would blow it up to the size of column 0, which tells the objects apart).
INSIDE_OLD = {o: ([c, 0.0], [1.0, 10.0]) for o, c in zip(OLD, (-10.0, 0.0, 10.0))}
INSIDE_NEW = {o: ([c + 0.3, 0.0], [1.0, 0.1]) for o, c in zip(NEW, (-10.0, 0.0, 10.0))}


def _check_choice(step, expected):
    other = "prior" if expected == "new" else "new"
    chosen = step.feature_space[ACTION]
    assert chosen["space"] == expected, (step.step, chosen)
    assert chosen["evidence"][expected] > chosen["evidence"][other], (step.step, chosen)
    row = step.as_row()
    assert row[f"space[{ACTION}]"] == expected
    assert row[f"space_evidence[{ACTION}].{other}"] == chosen["evidence"][other]


def test_new_objects_like_none_of_the_old_ones_get_their_own_space():
    """Once some new objects have been observed more than once, their labels are more probable
    in their own space, and that space is kept. With one observation per object (step 0) the
    labels cannot say which space tells the objects apart — each observation is its own
    object — so the early choices are not asserted."""
    learner, run = _learn(BEYOND_OLD, BEYOND_NEW, budget=8, feature_space="evidence")
    assert all(d.transfers for d in learner.learners[ACTION].decisions.values())
    for step in run.steps[3:]:
        _check_choice(step, "new")
    lrn = learner.learners[ACTION]
    assert lrn.space == "new" and lrn._test_cache[0] is not lrn.prior.pipeline
    rows = step_rows(run)
    assert all(r["updates"] == 1 for r in rows)
    assert sum(r["prior_space"] for r in rows[3:]) == 0


def test_new_objects_inside_the_old_objects_clusters_keep_the_prior_space():
    learner, run = _learn(INSIDE_OLD, INSIDE_NEW, budget=8, feature_space="evidence")
    assert all(d.transfers for d in learner.learners[ACTION].decisions.values())
    for step in run.steps:
        _check_choice(step, "prior")
    assert all(r["prior_space"] == r["updates"] == 1 for r in step_rows(run))
    # The kept model is the one the fixed space fits: the same run, the same curve.
    _, fixed = _learn(INSIDE_OLD, INSIDE_NEW, budget=8, feature_space="prior")
    assert [s.mean_accuracy for s in run.steps] == [s.mean_accuracy for s in fixed.steps]


def test_the_constructed_worlds_reward_the_chosen_space():
    """The worlds above are what they claim: in each, the chosen space classifies the new
    objects' test observations better than the other, over a run of 8 observations."""
    for old, new, good, bad in (
        (BEYOND_OLD, BEYOND_NEW, "new", "prior"),
        (INSIDE_OLD, INSIDE_NEW, "prior", "new"),
    ):
        acc = {
            s: np.mean([st.mean_accuracy for st in _learn(old, new, 8, feature_space=s)[1].steps])
            for s in (good, bad)
        }
        assert acc[good] > acc[bad] + 0.2, acc


def test_nothing_transferred_is_the_baseline_without_a_second_fit(monkeypatch):
    """When the cut-off stops every transfer, "evidence" is "auto": the baseline's space, no
    comparison."""
    calls = []
    fit = ActionLearner._fit

    def counting(self, pipeline, step, X_prior):
        calls.append(pipeline)
        return fit(self, pipeline, step, X_prior)

    monkeypatch.setattr(ActionLearner, "_fit", counting)
    learner, run = _learn(BEYOND_OLD, BEYOND_NEW, budget=2, feature_space="evidence", eps_neg=1.0)
    assert not any(d.transfers for d in learner.learners[ACTION].decisions.values())
    assert len(calls) == len(run.steps)
    for step in run.steps:
        assert step.feature_space[ACTION] == {"space": "new", "evidence": {}}


# -- no number from a candidate -------------------------------------------------------------------
def test_choose_space_falls_back_to_the_prior_space_on_ties_and_missing_numbers():
    both = ("prior", "new")
    assert choose_space({"prior": -3.0, "new": -2.0}, both) == "new"
    assert choose_space({"prior": -2.0, "new": -3.0}, both) == "prior"
    assert choose_space({"prior": -2.0, "new": -2.0}, both) == "prior"
    assert choose_space({"prior": np.nan, "new": -9.0}, both) == "new"
    assert choose_space({"prior": -9.0, "new": np.nan}, both) == "prior"
    assert choose_space({"prior": -np.inf, "new": -9.0}, both) == "new"
    assert choose_space({"prior": np.nan, "new": np.nan}, both) == "prior"
    assert choose_space({"prior": -1.0, "new": -5.0}, ("new",)) == "new"


def test_a_candidate_whose_fit_fails_loses(monkeypatch):
    fit = ActionLearner._fit

    def failing_in_new(self, pipeline, step, X_prior):
        if pipeline is not self.prior.pipeline:
            raise KernelNotPositiveDefiniteError("constructed failure")
        return fit(self, pipeline, step, X_prior)

    monkeypatch.setattr(ActionLearner, "_fit", failing_in_new)
    _, run = _learn(BEYOND_OLD, BEYOND_NEW, budget=1, feature_space="evidence")
    for step in run.steps:
        chosen = step.feature_space[ACTION]
        assert chosen["space"] == "prior" and np.isnan(chosen["evidence"]["new"])

    def failing(self, pipeline, step, X_prior):
        raise KernelNotPositiveDefiniteError("constructed failure")

    monkeypatch.setattr(ActionLearner, "_fit", failing)
    with pytest.raises(KernelNotPositiveDefiniteError):
        _learn(BEYOND_OLD, BEYOND_NEW, budget=0, feature_space="evidence")
