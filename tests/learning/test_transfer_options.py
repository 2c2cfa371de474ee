"""The learner's transfer options (issue 11): relatedness, the paper's baseline and the control,
stress-test choices, several sources, and the hyper-parameters recorded per step."""

import numpy as np
import pytest

from aptkt.gp import uniform_class_prior
from aptkt.learning import (
    APTKT,
    FeaturePipeline,
    GPSettings,
    LearnerConfig,
    PoolEnvironment,
    PriorKnowledge,
)
from aptkt.learning.active import entropy
from aptkt.learning.learner import hyperparameters
from aptkt.learning.prior import binary_probabilities
from aptkt.learning.transfer import decide_transfer

from .synthetic import ACTIONS, draw, make_world

OLD = ["a", "b", "c", "d"]


# -- Eq. 3 variants on hand-made probabilities ------------------------------------------------
def test_multi_transfers_every_old_object_above_the_cut_off_with_its_own_lambda():
    p = np.array([[0.7, 0.5, 0.1, 0.45], [0.5, 0.5, 0.2, 0.35]])  # p̄ = 0.6, 0.5, 0.15, 0.4
    d = decide_transfer("n", OLD, p, eps_neg=0.4, mode="multi")
    assert d.sources == ("a", "b", "d")
    assert d.lambdas == pytest.approx((0.6, 0.5, 0.4))
    assert d.as_dict()["sources"] == pytest.approx({"a": 0.6, "b": 0.5, "d": 0.4})
    # The paper's mode keeps only the most related one.
    paper = decide_transfer("n", OLD, p, eps_neg=0.4, mode="paper")
    assert paper.sources == ("a",) and paper.transfer_lambda == pytest.approx(0.6)
    assert decide_transfer("n", OLD, p, eps_neg=0.65, mode="multi").sources == ()


def test_stress_choice_least_related_and_forced_lambda_respect_the_cut_off():
    p = np.array([[0.7, 0.5, 0.1, 0.45]])
    # Without a cut-off the least related prior is transferred with the forced λ.
    d = decide_transfer("n", OLD, p, eps_neg=0.0, choice="least", forced_lambda=1.0)
    assert d.source == "c" and d.transfer_lambda == 1.0
    # The cut-off judges the chosen object's own p̄ (0.1): nothing passes.
    cut = decide_transfer("n", OLD, p, eps_neg=0.4, choice="least", forced_lambda=1.0)
    assert not cut.transfers and cut.transfer_lambda == 0.0
    # λ = 1 from the most related one once it passes.
    most = decide_transfer("n", OLD, p, eps_neg=0.4, forced_lambda=1.0)
    assert most.source == "a" and most.transfer_lambda == 1.0
    for mode in ("none", "control"):
        assert not decide_transfer("n", OLD, p, eps_neg=0.0, mode=mode).transfers
    with pytest.raises(ValueError, match="choice"):
        decide_transfer("n", OLD, p, eps_neg=0.4, choice="random")
    with pytest.raises(ValueError, match="forced_lambda"):
        decide_transfer("n", OLD, p, eps_neg=0.4, forced_lambda=1.5)


def test_config_validates_the_options_and_round_trips():
    cfg = LearnerConfig(
        transfer="control", source="positives", relatedness="normalised", forced_lambda=1.0
    )
    assert LearnerConfig.from_dict(cfg.to_dict()) == cfg
    assert cfg.uses_prior and not cfg.transfers
    assert not LearnerConfig(transfer="none").uses_prior
    assert LearnerConfig(transfer="none", auxiliary=True).uses_prior
    for field, bad in (
        ("transfer", "bold"),
        ("source", "negatives"),
        ("relatedness", "cosine"),
        ("source_choice", "random"),
    ):
        with pytest.raises(ValueError, match=field):
            LearnerConfig(**{field: bad})
    with pytest.raises(ValueError, match="forced_lambda"):
        LearnerConfig(forced_lambda=-0.1)


# -- relatedness from the old models ----------------------------------------------------------
def _world_with_irrelevant_priors(n_irrelevant, seed=7, gp=None):
    """One old object ("old0") that new object "new0" is like, and ``n_irrelevant`` old objects
    far from every new object."""
    rng = np.random.default_rng(seed)
    means = {}
    for a, mods in ACTIONS.items():
        rel = {m: rng.normal(scale=4.0, size=d) for m, d in mods.items()}
        means[(a, "old0")] = rel
        means[(a, "new0")] = {m: v + 0.3 for m, v in rel.items()}
        means[(a, "new1")] = {m: rng.normal(scale=4.0, size=d) - 30 for m, d in mods.items()}
        for k in range(n_irrelevant):
            means[(a, f"old{k + 1}")] = {
                m: rng.normal(scale=4.0, size=d) + 30 + 12 * k for m, d in mods.items()
            }
    priors = [f"old{k}" for k in range(n_irrelevant + 1)]
    prior = PriorKnowledge.build(draw(means, priors, 15, seed=1), seed=0, gp=gp)
    news = draw(means, ["new0", "new1"], 4, seed=2)
    return prior, news


def _relatedness_of_new0(n_irrelevant, kind):
    prior, news = _world_with_irrelevant_priors(n_irrelevant)
    out = {}
    for action in ACTIONS:
        ap = prior[action]
        X, _ = ap.features(news[action])
        p = ap.relatedness(X, kind)[news[action].objects == "new0"]
        out[action] = decide_transfer("new0", ap.objects, p, LearnerConfig().eps_neg)
    return out


def test_binary_relatedness_does_not_depend_on_the_number_of_priors():
    """ε_neg means the same whatever the number of priors: with binary relatedness the related
    prior passes the cut-off, with the same p̄, with one irrelevant prior beside it and with
    five. The normalised posterior's p̄ of the same prior falls as irrelevant priors are added."""
    few, many = _relatedness_of_new0(1, "binary"), _relatedness_of_new0(5, "binary")
    for action in ACTIONS:
        for d in (few[action], many[action]):
            assert d.source == "old0", (action, d.as_dict())
            assert d.transfer_lambda > 0.7
            # Every irrelevant prior's own classifier claims new0 less than old0's does.
            assert max(d.mean_posterior[1:]) < d.transfer_lambda - 0.2
        assert many[action].transfer_lambda == pytest.approx(few[action].transfer_lambda, abs=0.1)
    few_n, many_n = _relatedness_of_new0(1, "normalised"), _relatedness_of_new0(5, "normalised")
    for action in ACTIONS:
        assert many_n[action].mean_posterior[0] < few_n[action].mean_posterior[0] - 0.1


def test_binary_probabilities_normalise_to_the_class_posterior():
    """Independent check of the binary probabilities: normalising them over the classes gives
    the model's class posterior (both with the exact predictive integral)."""
    exact = GPSettings(approximation="quadrature")
    prior, news = _world_with_irrelevant_priors(3, gp=exact)
    ap = prior["P1"]
    X, _ = ap.features(news["P1"])
    b = binary_probabilities(ap.model, X)
    assert b.shape == (X.shape[0], 4) and np.all((b > 0) & (b < 1))
    np.testing.assert_allclose(b / b.sum(axis=1, keepdims=True), ap.posteriors(X), atol=1e-3)
    assert not np.allclose(b.sum(axis=1), 1.0)  # not a posterior over old objects
    # Two old objects: one classifier; the binary probabilities are the class posterior.
    two, news2 = _world_with_irrelevant_priors(1, gp=exact)
    X2, _ = two["P1"].features(news2["P1"])
    np.testing.assert_allclose(
        binary_probabilities(two["P1"].model, X2), two["P1"].posteriors(X2), atol=1e-3
    )


# -- baseline, control and records --------------------------------------------------------------
@pytest.fixture(scope="module")
def world():
    priors, news, means = make_world(
        n_prior=3, n_new=3, noise=1.0, separation=0.6, related=True, seed=1
    )
    return dict(
        news=news,
        prior=PriorKnowledge.build(draw(means, priors, 12, seed=1), seed=0),
        pool=draw(means, news, 10, seed=2),
        test=draw(means, news, 6, seed=3),
    )


def _run(world, budget=2, prior="given", **cfg):
    learner = APTKT(
        LearnerConfig(budget=budget, seed=1, **cfg), world["prior"] if prior == "given" else None
    )
    run = learner.run(
        PoolEnvironment(world["pool"], seed=1), list(ACTIONS), world["news"], world["test"]
    )
    return learner, run


def test_baseline_uses_nothing_of_the_prior(world):
    with_prior, run_a = _run(world, transfer="none")
    _, run_b = _run(world, transfer="none", prior=None)
    assert run_a.prior_objects == []
    assert _same_rows(run_a.rows(), run_b.rows())
    for learner in with_prior.learners.values():
        assert learner.prior is None
        # Its feature transforms are fitted on the new objects' training observations.
        own = FeaturePipeline().fit(learner.observations)
        got = learner._pipeline(transfers=False)
        for m in own.modality_names_:
            np.testing.assert_allclose(got.transforms[m].mean_, own.transforms[m].mean_)
        assert not learner.decisions


def _same_rows(a, b):
    # repr: NaN (no uncertainty at step 0) compares equal to itself.
    def strip(rows):
        return repr([{k: v for k, v in r.items() if k != "seconds"} for r in rows])

    return strip(a) == strip(b)


def test_control_works_in_the_prior_feature_space_without_transfer(world):
    learner, run = _run(world, transfer="control")
    assert run.prior_objects == world["prior"].objects
    for a, lrn in learner.learners.items():
        assert lrn._pipeline(transfers=False) is world["prior"][a].pipeline
        assert not lrn.decisions and not lrn.model.sources_
    assert all(not s.transfer or not any(s.transfer.values()) for s in run.steps)


def test_hyperparameters_of_every_classifier_are_recorded(world):
    learner, run = _run(world, transfer="paper", budget=1)
    step = run.steps[-1]
    for a, lrn in learner.learners.items():
        assert step.hyperparameters[a] == hyperparameters(lrn.model)
        assert set(step.hyperparameters[a]) == set(world["news"])
        for c, hp in step.hyperparameters[a].items():
            i = list(lrn.model.classes_).index(c)
            assert hp["signal_variance"] == pytest.approx(lrn.model.signal_variance_[i])
            names = lrn.model.modality_names_
            for k, m in enumerate(names):
                assert hp[f"length_scale[{m}]"] == pytest.approx(lrn.model.length_scales_[i, k])
                assert hp[f"weight[{m}]"] == pytest.approx(lrn.model.modality_weights_[i, k])
            d = lrn.decisions[c]
            lambdas = {k: v for k, v in hp.items() if k.startswith("lambda[")}
            assert lambdas == pytest.approx(
                {f"lambda[{o}]": lam for o, lam in zip(d.sources, d.lambdas)}
            )
    row = step.as_row()
    a, c = "P1", world["news"][0]
    assert row[f"hp[{a}][{c}].signal_variance"] == step.hyperparameters[a][c]["signal_variance"]
    everything = [hp for per in step.hyperparameters.values() for hp in per.values()]
    assert row["median_signal_variance"] == pytest.approx(
        np.median([hp["signal_variance"] for hp in everything])
    )
    # Two classes without transfer: one classifier serves both, both list its values.
    two = {a: obs.of_objects(world["news"][:2]) for a, obs in world["pool"].items()}
    base = APTKT(LearnerConfig(transfer="none", budget=0)).run(
        PoolEnvironment(two), list(ACTIONS), world["news"][:2]
    )
    two_hp = base.steps[0].hyperparameters["P1"]
    assert set(two_hp) == set(world["news"][:2])
    assert two_hp[world["news"][0]] == two_hp[world["news"][1]]


def test_transfer_from_a_related_prior_is_not_inert(world):
    """With a related prior and λ = p̄, the transfer changes the new objects' predictions
    materially at one observation per object, against the control (same feature space, no
    transfer), and not for the worse."""
    test = world["test"]
    changes, gains = [], []
    for seed in range(3):
        post = {}
        for transfer in ("paper", "control"):
            learner = APTKT(LearnerConfig(transfer=transfer, budget=0, seed=seed), world["prior"])
            run = learner.run(
                PoolEnvironment(world["pool"], seed=seed), list(ACTIONS), world["news"], test
            )
            post[transfer] = (
                {a: lrn.test_posteriors for a, lrn in learner.learners.items()},
                run.steps[0].mean_accuracy,
            )
            if transfer == "paper":
                lambdas = [
                    d.transfer_lambda
                    for lrn in learner.learners.values()
                    for d in lrn.decisions.values()
                ]
                assert np.mean(lambdas) > 0.5  # related priors pass the cut-off
        for a in ACTIONS:
            changes.append(np.abs(post["paper"][0][a] - post["control"][0][a]).mean())
        gains.append(post["paper"][1] - post["control"][1])
    assert np.mean(changes) > 0.1, changes
    assert np.mean(gains) > 0.05, gains


def test_one_vs_all_sources_and_several_sources_reach_the_classifiers(world):
    """The default source task is the chosen old object's one-vs-all data; "multi" hands every
    old object above the cut-off to the classifier, each with its own λ."""
    prior = world["prior"]
    learner, _ = _run(world, transfer="multi", budget=0, eps_neg=0.0, cutoff="paper")
    n_old = {a: len(prior[a].observations) for a in ACTIONS}
    for a, lrn in learner.learners.items():
        for c, d in lrn.decisions.items():
            assert len(d.sources) == len(prior.objects)  # ε_neg = 0: every old object
            got = lrn.model.sources_[c]
            assert [s.name for s in got] == list(d.sources)
            assert [s.transfer_lambda for s in got] == pytest.approx(list(d.lambdas))
            for s in got:
                assert s.X.shape[0] == n_old[a]
                mine = prior[a].observations.objects == s.name
                np.testing.assert_array_equal(s.y, np.where(mine, 1.0, -1.0))
    paper, _ = _run(world, transfer="paper", budget=0, source="positives")
    for a, lrn in paper.learners.items():
        for _c, srcs in lrn.model.sources_.items():
            (s,) = srcs
            assert s.y is None
            assert s.X.shape[0] == int(np.sum(prior[a].observations.objects == s.name))


def _unrelated_world() -> dict:
    """New objects like none of the 3 priors (their means drawn apart)."""
    priors, news, means = make_world(n_prior=3, n_new=3, separation=0.6, related=False, seed=1)
    return dict(
        news=news,
        prior=PriorKnowledge.build(draw(means, priors, 12, seed=1), seed=0),
        pool=draw(means, news, 10, seed=2),
        test=draw(means, news, 6, seed=3),
    )


def test_feature_space_auto_uses_nothing_of_an_irrelevant_prior():
    """feature_space="auto": when the cut-off stops every transfer, APTKT is the baseline
    exactly; when something transfers, the model lives in the prior's feature space. "new"
    never uses the prior's space, "prior" always does."""
    far = _unrelated_world()
    aptkt, run = _run(far, transfer="paper", budget=3)
    assert all(not d.transfers for lrn in aptkt.learners.values() for d in lrn.decisions.values())
    _, base = _run(far, transfer="none", budget=3)
    strip = lambda rows: [  # noqa: E731
        {k: v for k, v in r.items() if k in ("mean_accuracy", "fused_accuracy", "action")}
        for r in rows
    ]
    assert strip(run.rows()) == strip(base.rows())
    in_prior, _ = _run(far, transfer="paper", budget=0, feature_space="prior")
    for a, lrn in in_prior.learners.items():
        assert lrn._pipeline(transfers=False) is far["prior"][a].pipeline
    # Related priors: "auto" transfers, in the prior's space; "new" keeps its own.
    for space, expect_prior in (("auto", True), ("new", False)):
        learner, _ = _run(_related(), transfer="paper", budget=0, feature_space=space)
        for _a, lrn in learner.learners.items():
            assert any(d.transfers for d in lrn.decisions.values())
            assert (lrn._pipeline(transfers=True) is lrn.prior.pipeline) == expect_prior


def _related():
    priors, news, means = make_world(
        n_prior=3, n_new=3, noise=1.0, separation=0.6, related=True, seed=1
    )
    return dict(
        news=news,
        prior=PriorKnowledge.build(draw(means, priors, 12, seed=1), seed=0),
        pool=draw(means, news, 10, seed=2),
        test=draw(means, news, 6, seed=3),
    )


# -- the evidence cut-off ("like none of them") ---------------------------------------------------
def test_evidence_filters_what_passed_eps_neg_and_paper_is_eq3_exactly():
    p = np.array([[0.7, 0.5, 0.1, 0.45], [0.5, 0.5, 0.2, 0.35]])  # p̄ = 0.6, 0.5, 0.15, 0.4
    asked = []

    def evidence(old, lam):
        asked.append((old, lam))
        return {"a": -0.3, "b": 0.8, "c": -5.0, "d": 2.0}[old]

    d = decide_transfer("n", OLD, p, eps_neg=0.4, mode="multi", evidence=evidence)
    # Only the old objects that passed ε_neg are tested, each at its own λ.
    assert asked == [
        ("a", pytest.approx(0.6)),
        ("b", pytest.approx(0.5)),
        ("d", pytest.approx(0.4)),
    ]
    assert d.sources == ("b", "d") and d.lambdas == pytest.approx((0.5, 0.4))
    assert d.as_dict()["log_bayes_factor"] == pytest.approx({"a": -0.3, "b": 0.8, "d": 2.0})
    # The margin is a log Bayes factor the transfer must exceed.
    assert decide_transfer(
        "n", OLD, p, eps_neg=0.4, mode="multi", evidence=evidence, evidence_margin=1.0
    ).sources == ("d",)
    # The paper's mode: the most related object only; rejected by its evidence, nothing else
    # is tried.
    paper = decide_transfer("n", OLD, p, eps_neg=0.4, evidence=evidence)
    assert not paper.transfers and paper.as_dict()["log_bayes_factor"] == {"a": -0.3}
    # Without an evidence function Eq. 3 alone decides (cutoff="paper").
    plain = decide_transfer("n", OLD, p, eps_neg=0.4)
    assert plain.sources == ("a",) and plain.evidence == ()
    # The stress test's forced λ is the one the evidence is asked about.
    asked.clear()
    stress = decide_transfer(
        "n", OLD, p, eps_neg=0.0, choice="least", forced_lambda=1.0, evidence=evidence
    )
    assert asked == [("c", 1.0)] and not stress.transfers


def test_cutoff_option_validates_and_round_trips():
    cfg = LearnerConfig(cutoff="paper", evidence_margin=1.0)
    assert LearnerConfig.from_dict(cfg.to_dict()) == cfg
    assert LearnerConfig().cutoff == "evidence" and LearnerConfig().evidence_margin == 0.0
    with pytest.raises(ValueError, match="cutoff"):
        LearnerConfig(cutoff="support")
    with pytest.raises(ValueError, match="evidence_margin"):
        LearnerConfig(evidence_margin=float("nan"))
    lnn = LearnerConfig(evidence_margin=None)
    assert LearnerConfig.from_dict(lnn.to_dict()) == lnn


def test_evidence_margin_none_is_ln_of_the_number_of_old_objects(world):
    """None: prior odds 1/N_old of "like old object i" against "like none of them"."""
    learner, _ = _run(world, transfer="paper", budget=0, evidence_margin=None)
    for lrn in learner.learners.values():
        assert lrn._evidence_margin() == pytest.approx(np.log(3))
        for d in lrn.decisions.values():
            for old, log_bf in d.evidence:
                assert (old in d.sources) == (log_bf > np.log(3))
    fixed, _ = _run(world, transfer="paper", budget=0, evidence_margin=0.25)
    assert all(lrn._evidence_margin() == 0.25 for lrn in fixed.learners.values())


def _laplace_log_evidence(K, y):
    """Laplace approximation of log p(y | K) for a binary GPC with the logistic likelihood,
    written out from Rasmussen & Williams Algorithm 3.1 and Eq. 3.32 (an independent check of
    the core's)."""
    n = len(y)
    f = np.zeros(n)
    for _ in range(200):
        pi = 1.0 / (1.0 + np.exp(-f))
        W = pi * (1 - pi)
        sw = np.sqrt(W)
        L = np.linalg.cholesky(np.eye(n) + sw[:, None] * K * sw[None, :])
        b = W * f + (y + 1) / 2 - pi
        a = b - sw * np.linalg.solve(L.T, np.linalg.solve(L, sw * (K @ b)))
        f_new = K @ a
        if np.max(np.abs(f_new - f)) < 1e-12:
            f = f_new
            break
        f = f_new
    log_lik = -np.sum(np.log1p(np.exp(-y * f)))
    return -0.5 * a @ f + log_lik - np.sum(np.log(np.diag(L)))


def test_transfer_evidence_is_the_laplace_bayes_factor(world):
    """The evidence of a transfer, against an independent Laplace computation: log Z of the
    joint (source, target) task with the cross block scaled by λ, minus log Z with λ = 0,
    which is the source's log Z plus the target's."""
    ap = world["prior"]["P1"]
    new = world["pool"]["P1"]
    X_new, _ = ap.features(new)
    X_new, objects = X_new[::3], new.objects[::3]  # a few observations of each new object
    positive = objects == world["news"][0]
    old = ap.objects[0]
    hp = ap.model.hyperparameters_[old]
    X_old = ap.training_features()
    y_old = np.where(ap.observations.objects == old, 1.0, -1.0)
    y_new = np.where(positive, 1.0, -1.0)

    def rbf(A, B):
        k = 0.0
        for m, cols in zip(ap.model.modality_names_, ap.model.modalities_):
            d2 = ((A[:, None, cols] - B[None, :, cols]) ** 2).sum(-1)
            k = k + hp["modality_weights"][m] * np.exp(-d2 / (2 * hp["length_scales"][m] ** 2))
        return hp["signal_variance"] * k

    def joint(lam):
        K = np.block(
            [
                [rbf(X_old, X_old), lam * rbf(X_old, X_new)],
                [lam * rbf(X_new, X_old), rbf(X_new, X_new)],
            ]
        )
        return _laplace_log_evidence(K, np.concatenate([y_old, y_new]))

    for lam in (0.3, 0.9):
        expected = joint(lam) - joint(0.0)
        got = ap.transfer_evidence(X_new, positive, old, lam)
        assert got == pytest.approx(expected, abs=1e-6)
    # λ = 0 is the independent model itself, and its evidence factorises.
    assert ap.transfer_evidence(X_new, positive, old, 0.0) == pytest.approx(0.0, abs=1e-9)
    sep = _laplace_log_evidence(rbf(X_old, X_old), y_old) + _laplace_log_evidence(
        rbf(X_new, X_new), y_new
    )
    assert joint(0.0) == pytest.approx(sep, abs=1e-8)
    with pytest.raises(ValueError, match="positive"):
        ap.transfer_evidence(X_new, np.ones(len(X_new), bool), old, 0.5)


def test_transfer_evidence_reuses_only_the_source_factor(world):
    """The evidence test keeps the source task's log Z from one call to the next (it depends on
    the old object and the kind of source only): interleaved calls with other new observations,
    other λ, other old objects and both kinds of source give what a fresh joint model at λ and
    at λ = 0 gives."""
    from aptkt.gp import TransferSource
    from aptkt.learning.evidence import at_fitted_hyperparameters, coupling_evidence
    from aptkt.learning.prior import ActionPrior

    base = world["prior"]["P1"]
    ap = ActionPrior(base.action, base.observations, base.pipeline, base.model)  # empty cache
    new = world["pool"]["P1"]
    X_all, _ = ap.features(new)
    X_old = ap.training_features()
    cases = []
    for start, source, old, lam in (
        (0, "one-vs-all", ap.objects[0], 0.6),
        (1, "positives", ap.objects[0], 0.9),
        (2, "one-vs-all", ap.objects[1], 0.4),
        (1, "one-vs-all", ap.objects[0], 0.8),
        (0, "positives", ap.objects[0], 0.5),
    ):
        X_new, objects = X_all[start::3], new.objects[start::3]
        positive = objects == world["news"][start % len(world["news"])]
        cases.append((X_new, positive, old, lam, source))
    for X_new, positive, old, lam, source in cases:
        got = ap.transfer_evidence(X_new, positive, old, lam, source)
        mine = np.asarray(ap.observations.objects) == old
        task = (
            TransferSource(X_old[mine], transfer_lambda=lam)
            if source == "positives"
            else TransferSource(X_old, np.where(mine, 1.0, -1.0), transfer_lambda=lam)
        )
        fresh = at_fitted_hyperparameters(ap.model, old).fit(
            X_new, positive.astype(int), sources={1: task}
        )
        assert got == pytest.approx(
            coupling_evidence(fresh, 1 if fresh.theta_.shape[0] > 1 else 0), abs=1e-8
        )
    assert set(ap._source_evidence) == {
        (ap.objects[0], "one-vs-all"),
        (ap.objects[0], "positives"),
        (ap.objects[1], "one-vs-all"),
    }


def _beyond_world(far, seed=1):
    """New objects like none of the old ones: each lies beyond old0, on the side away from the
    other old objects (at ``far`` times old0's distance from them), scattered around that
    point. Old0's one-vs-all classifier claims them all; none is like old0."""
    priors, news, means = make_world(
        n_prior=3, n_new=3, noise=1.0, separation=0.6, related=True, seed=seed
    )
    rng = np.random.default_rng(seed + 100)
    for a, mods in ACTIONS.items():
        for o in news:
            means[(a, o)] = {}
            for m in mods:
                m0 = means[(a, priors[0])][m]
                away = m0 - (means[(a, priors[1])][m] + means[(a, priors[2])][m]) / 2
                means[(a, o)][m] = m0 + far * away + rng.normal(size=m0.size)
    return dict(
        news=news,
        prior=PriorKnowledge.build(draw(means, priors, 12, seed=1), seed=0),
        pool=draw(means, news, 10, seed=2),
        test=draw(means, news, 6, seed=3),
    )


def test_evidence_stops_transfer_to_objects_like_none_of_the_old_ones():
    far = _beyond_world(far=1.0)
    paper, _ = _run(far, transfer="paper", budget=0, cutoff="paper")
    evidence, run = _run(far, transfer="paper", budget=0, cutoff="evidence")
    for a in ACTIONS:
        # Eq. 3 alone: old0's classifier claims every new object (p̄ ≥ ε_neg) ...
        for d in paper.learners[a].decisions.values():
            assert d.source == "old0" and d.transfer_lambda >= 0.5, d.as_dict()
        # ... the new objects' own labels do not favour it: no transfer.
        for d in evidence.learners[a].decisions.values():
            assert not d.transfers, d.as_dict()
            ((old, log_bf),) = d.evidence
            assert old == "old0" and log_bf < 0
    # Nothing transferred: APTKT is the baseline.
    _, base = _run(far, transfer="none", budget=0)
    assert run.steps[0].mean_accuracy == base.steps[0].mean_accuracy


def test_evidence_keeps_transfer_from_the_old_object_a_new_one_is_like(world):
    """Each new object inside one old object's cluster: the evidence favours every transfer
    Eq. 3 makes, and the decisions are Eq. 3's."""
    paper, _ = _run(world, transfer="paper", budget=0, cutoff="paper")
    evidence, _ = _run(world, transfer="paper", budget=0, cutoff="evidence")
    for a in ACTIONS:
        for o, d in evidence.learners[a].decisions.items():
            p = paper.learners[a].decisions[o]
            assert d.transfers and (d.source, d.lambdas) == (p.source, p.lambdas)
            assert dict(d.evidence)[d.source] > 0.5


def test_feature_space_covered_uses_the_prior_space_only_when_every_new_object_transfers(world):
    """ "covered": the prior's space when every new object of the action has a source, the
    baseline's otherwise; "auto" already when one has. ε_neg = 0.8 lets some new objects of
    each action through and stops the others (p̄ between 0.58 and 0.94 here)."""
    for space, partial_in_prior in (("auto", True), ("covered", False)):
        learner, _ = _run(world, transfer="paper", budget=0, eps_neg=0.8, feature_space=space)
        for a, lrn in learner.learners.items():
            made = [d.transfers for d in lrn.decisions.values()]
            assert any(made) and not all(made), (a, made)
            assert lrn._test_cache is not None
            assert (lrn._test_cache[0] is lrn.prior.pipeline) == partial_in_prior
    # Every new object transfers: both use the prior's space.
    learner, _ = _run(world, transfer="paper", budget=0, feature_space="covered")
    for lrn in learner.learners.values():
        assert all(d.transfers for d in lrn.decisions.values())
        assert lrn._test_cache is not None and lrn._test_cache[0] is lrn.prior.pipeline


def test_feature_space_pooled_fits_the_transforms_on_old_and_new_observations(world):
    """ "pooled": when the update transfers, the new objects' transforms are fitted on the old
    objects' observations and the new objects' training observations together (each counted
    once); scikit-learn's scaler and PCA on the concatenation are the reference. The source
    tasks are the old observations mapped into that space, and relatedness is judged in the
    prior's space, so the transfer decisions equal "auto"'s."""
    from sklearn.decomposition import PCA
    from sklearn.preprocessing import StandardScaler

    pooled, _ = _run(world, transfer="paper", budget=2, feature_space="pooled")
    auto, _ = _run(world, transfer="paper", budget=0, feature_space="auto")
    step0, _ = _run(world, transfer="paper", budget=0, feature_space="pooled")
    for a, lrn in step0.learners.items():
        for o, d in lrn.decisions.items():
            ref = auto.learners[a].decisions[o]
            assert (d.sources, d.lambdas) == (ref.sources, ref.lambdas)
    for a, lrn in pooled.learners.items():
        assert any(d.transfers for d in lrn.decisions.values())
        assert lrn._test_cache is not None
        pipe = lrn._test_cache[0]
        assert pipe is not lrn.prior.pipeline
        old = world["prior"][a].observations
        assert lrn.observations is not None and len(lrn.observations) > 0
        for m in pipe.modality_names_:
            X = np.vstack([old.modalities[m], lrn.observations.modalities[m]])
            t = pipe.transforms[m]
            if t.log_columns:
                cols = list(t.log_columns)
                X[:, cols] = np.log10(np.maximum(X[:, cols], 1e-12))
            scaler = StandardScaler().fit(X)
            np.testing.assert_allclose(t.mean_, scaler.mean_, rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(t.scale_, scaler.scale_, rtol=1e-10)
            # Neither population alone: the old observations' fit differs.
            assert not np.allclose(t.mean_, lrn.prior.pipeline.transforms[m].mean_)
            if t.components_ is not None:
                pca = PCA(n_components=t.components_.shape[0]).fit(scaler.transform(X))
                sign = np.sign(np.sum(pca.components_ * t.components_, axis=1))
                np.testing.assert_allclose(
                    t.components_ * sign[:, None], pca.components_, atol=1e-8
                )
                n = X.shape[0]
                sd0 = np.sqrt(pca.explained_variance_[0] * (n - 1) / n)
                assert t.pca_scale_ == pytest.approx(sd0, rel=1e-8)
        # The source tasks: every old observation (one-vs-all), mapped into the pooled space.
        X_old = pipe.transform(old)[0]
        for _c, srcs in lrn.model.sources_.items():
            for s in srcs:
                np.testing.assert_allclose(s.X, X_old)


def test_feature_space_pooled_is_the_baseline_when_nothing_transfers():
    far = _unrelated_world()
    aptkt, run = _run(far, transfer="paper", budget=3, feature_space="pooled")
    assert all(not d.transfers for lrn in aptkt.learners.values() for d in lrn.decisions.values())
    _, base = _run(far, transfer="none", budget=3)
    keys = ("mean_accuracy", "fused_accuracy", "action")
    strip = lambda rows: [{k: r[k] for k in keys} for r in rows]  # noqa: E731
    assert strip(run.rows()) == strip(base.rows())
    cfg = LearnerConfig(feature_space="pooled")
    assert LearnerConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError, match="feature_space"):
        LearnerConfig(feature_space="union")


def test_warm_start_is_off_by_default_and_not_in_the_recorded_config():
    assert LearnerConfig().warm_start is None
    # Absent at its default: run keys of results stored before the option stay valid.
    assert "warm_start" not in LearnerConfig().to_dict()
    cfg = LearnerConfig(warm_start="both")
    assert LearnerConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError, match="warm_start"):
        LearnerConfig(warm_start="always")


def _starts_seen(monkeypatch):
    from aptkt.gp import LaplaceGPC

    seen = []
    fit = LaplaceGPC.fit

    def spy(self, X, y, sources=None, *, hyperparameters=None):
        seen.append(hyperparameters)
        return fit(self, X, y, sources, hyperparameters=hyperparameters)

    monkeypatch.setattr(LaplaceGPC, "fit", spy)
    return seen


def test_warm_start_previous_starts_each_class_at_its_last_optimum(world, monkeypatch):
    seen = _starts_seen(monkeypatch)
    learner, run = _run(world, transfer="none", budget=3, prior=None, warm_start="previous")
    n_actions = len(ACTIONS)
    assert seen[:n_actions] == [{}] * n_actions  # nothing earlier at the first update
    # Every later update starts from the optimum that the step before recorded for its action.
    for k, step in enumerate(run.steps[1:], start=1):
        start = seen[n_actions + k - 1]
        before = run.steps[k - 1].hyperparameters[step.action]
        assert set(start) == set(world["news"])
        for c, hp in start.items():
            assert hp["signal_variance"] == pytest.approx(before[c]["signal_variance"])
            for m, v in hp["length_scales"].items():
                assert v == pytest.approx(before[c][f"length_scale[{m}]"])


def test_warm_start_source_starts_a_transferring_class_at_its_old_object(world, monkeypatch):
    seen = _starts_seen(monkeypatch)
    learner, _ = _run(
        world,
        transfer="paper",
        budget=0,
        cutoff="paper",
        eps_neg=0.0,
        warm_start="source",
        auxiliary=True,
    )
    prior = world["prior"]
    for (a, lrn), start in zip(learner.learners.items(), seen):
        old = prior[a].model.hyperparameters_
        transferring = {c for c, d in lrn.decisions.items() if d.transfers}
        assert transferring and set(start) == transferring
        for c in transferring:
            hp = old[lrn.decisions[c].sources[0]]
            assert start[c]["signal_variance"] == hp["signal_variance"]
            # The auxiliary modality is not the old classifier's: data-scaled, equal weight.
            assert start[c]["length_scales"] == hp["length_scales"]
            w = start[c]["modality_weights"]
            assert w["auxiliary"] == pytest.approx(1 / len(w))
            assert sum(w.values()) == pytest.approx(1.0)


def test_warm_starts_come_only_from_a_model_in_the_same_kind_of_space(world):
    """Length-scales are distances in one feature space: neither the previous optimum nor the
    old classifier's hyper-parameters seed a fit in another space."""
    learner, _ = _run(
        world,
        transfer="paper",
        budget=2,
        cutoff="paper",
        eps_neg=0.0,
        warm_start="both",
        feature_space="prior",
    )
    for lrn in learner.learners.values():
        assert lrn.space == "prior" and lrn.model is not None
        names = list(lrn.model.modality_names_)
        new_space = FeaturePipeline().fit(lrn.observations)
        in_prior = {
            c: [lrn._source(d.sources[0], d.lambdas[0], lrn.prior.pipeline)]
            for c, d in lrn.decisions.items()
            if d.transfers
        }
        in_new = {
            c: [lrn._source(d.sources[0], d.lambdas[0], new_space)]
            for c, d in lrn.decisions.items()
            if d.transfers
        }
        assert in_prior
        # The prior's space: the previous optimum for every class, the old classifier's where
        # a class transfers ("both").
        assert set(lrn._starts(names, in_prior, lrn.prior.pipeline)) == set(lrn.new_objects)
        # The new objects' own space: nothing to start from.
        assert lrn._starts(names, in_new, new_space) == {}


# -- the class posterior under actively chosen class counts ---------------------------------------
def test_class_prior_is_uniform_by_default_and_training_is_recorded_as_before():
    assert GPSettings().class_prior == "uniform"
    assert LearnerConfig().to_dict()["gp"]["class_prior"] == "uniform"
    # "training" is left out, as before the option existed: run keys of results stored then
    # stay valid, and a record without the field reads back as "training".
    training = LearnerConfig(gp=GPSettings(class_prior="training"))
    assert "class_prior" not in training.to_dict()["gp"]
    assert LearnerConfig.from_dict(training.to_dict()) == training
    assert LearnerConfig.from_dict(LearnerConfig().to_dict()) == LearnerConfig()
    with pytest.raises(ValueError, match="class_prior"):
        GPSettings(class_prior="balanced")


def test_modality_weight_prior_is_on_by_default_and_recorded_so_old_runs_keep_their_reading():
    from aptkt.gp import HyperPrior

    weak = GPSettings()
    made = weak.make({"a": [0], "b": [1]}, random_state=0).hyper_prior
    assert HyperPrior.resolve(made) == HyperPrior.weak()
    assert HyperPrior.weak().modality_weight_sd == pytest.approx(np.log(10.0) / np.sqrt(2.0))
    flat = GPSettings(modality_weight_prior=False)
    made = flat.make({"a": [0], "b": [1]}, random_state=0).hyper_prior
    assert made.modality_weight_sd is None
    assert made.length_scale_sd == HyperPrior.weak().length_scale_sd
    # Recorded at its default; a record without it was written with flat weights.
    assert weak.to_dict()["modality_weight_prior"] is True
    assert "modality_weight_prior" not in flat.to_dict()
    for gp in (weak, flat, GPSettings(hyper_prior=None)):
        cfg = LearnerConfig(gp=gp)
        assert LearnerConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError, match="modality_weight_prior"):
        GPSettings(modality_weight_prior="yes")


def test_optimizer_tolerance_is_the_learners_choice_recorded_and_checked():
    from aptkt.gp import DEFAULTS, LaplaceGPC

    assert GPSettings().optimizer_tol == 1e-6
    assert GPSettings().make({"a": [0], "b": [1]}, random_state=0).optimizer_tol == 1e-6
    assert LaplaceGPC().optimizer_tol == DEFAULTS.optimizer_tol
    # Recorded at the learner's default; a record without it was fitted at scipy's rule.
    assert GPSettings().to_dict()["optimizer_tol"] == 1e-6
    scipy = GPSettings(optimizer_tol=DEFAULTS.optimizer_tol)
    assert "optimizer_tol" not in scipy.to_dict()
    assert GPSettings.from_dict(scipy.to_dict()) == scipy
    for bad in (-1e-6, float("nan"), float("inf"), "1e-6", True, None):
        with pytest.raises(ValueError, match="optimizer_tol"):
            GPSettings(optimizer_tol=bad)
    # A saved estimator at the default keeps the parameter out (files stay readable by the
    # versions before it); another value is written.
    X = np.array([[0.0], [0.1], [1.0], [1.1]])
    y = np.array([0, 0, 1, 1])
    assert "optimizer_tol" not in _saved_params(LaplaceGPC(optimize=False).fit(X, y))
    loose = LaplaceGPC(optimize=False, optimizer_tol=1e-6).fit(X, y)
    assert _saved_params(loose)["optimizer_tol"] == 1e-6
    assert LaplaceGPC.from_state(loose.state()).optimizer_tol == 1e-6


def _saved_params(model):
    import json

    return json.loads(model.state()["meta"].tobytes())["params"]


def test_step_records_equal_values_computed_afresh_at_every_step(world):
    """Each action's accuracy and hyper-parameters are kept until its next refit; every step's
    record must still equal a fresh computation from the learners at that step, also when the
    fitted cut-off replaces a model by a refit."""
    from aptkt.learning.evaluation import accuracy

    learner = APTKT(LearnerConfig(budget=6, seed=1, cutoff="fitted"), world["prior"])
    checked = []

    def compare(record):
        for a, lrn in learner.learners.items():
            classes = [str(c) for c in lrn.model.classes_]
            fresh = accuracy(lrn.test_posteriors, classes, [str(o) for o in lrn.test_objects])
            assert record.accuracy[a] == fresh
            assert record.hyperparameters[a] == hyperparameters(lrn.model)
        checked.append(record.step)

    learner.run(
        PoolEnvironment(world["pool"], seed=1),
        list(ACTIONS),
        world["news"],
        world["test"],
        on_step=compare,
    )
    assert checked == list(range(7))


def test_the_learner_takes_the_actively_chosen_counts_out_of_its_posteriors(world):
    for class_prior in ("uniform", "training"):
        learner, run = _run(
            world, transfer="none", budget=4, prior=None, gp=GPSettings(class_prior=class_prior)
        )
        for lrn in learner.learners.values():
            assert lrn.model.class_prior == class_prior
            X_test = lrn._test_cache[1]
            binary = lrn.model.predict_proba_binary(X_test)
            counts = np.array([np.sum(lrn.observations.objects == c) for c in lrn.model.classes_])
            np.testing.assert_array_equal(lrn.model.class_counts_, counts)
            expected = (
                uniform_class_prior(binary, counts / counts.sum())
                if class_prior == "uniform"
                else binary / binary.sum(axis=1, keepdims=True)
            )
            np.testing.assert_allclose(lrn.test_posteriors, expected, rtol=1e-9)
            # The selection scores the training observations under the frequencies they were
            # drawn with, whatever the setting.
            fitted = lrn.model.predict_proba_binary(lrn.model.X_train_)
            np.testing.assert_allclose(
                lrn.train_entropy,
                entropy(fitted / fitted.sum(axis=1, keepdims=True)),
                rtol=1e-9,
                atol=1e-12,
            )
        # Four observations after the initial round over 2 actions × 3 objects: no split of 4
        # gives every object of both actions the same count, so the counts are uneven
        # somewhere and the two settings are not the same posterior there.
        assert any(len(set(lrn.model.class_counts_)) > 1 for lrn in learner.learners.values())


def test_feature_space_blended_counts_each_old_object_as_one_observation(world):
    """ "blended": when the update transfers, the transforms are those of the new training
    observations (weight 1 each) together with the old objects, each old object's observations
    sharing a weight of 1 — the mean against the formula, early and later in a run."""
    early, _ = _run(world, transfer="paper", budget=0, feature_space="blended")
    late, _ = _run(world, transfer="paper", budget=6, feature_space="blended")
    auto, _ = _run(world, transfer="paper", budget=0, feature_space="auto")
    checked = 0
    for learner in (early, late):
        for a, lrn in learner.learners.items():
            if not any(d.transfers for d in lrn.decisions.values()):
                continue
            assert lrn.space == "blended"
            pipe = lrn._test_cache[0]
            old = world["prior"][a].observations
            new = lrn.observations
            objects, counts = np.unique(old.objects, return_counts=True)
            per_row = 1.0 / counts[np.searchsorted(objects, old.objects)]
            m = next(m for m in pipe.modality_names_ if not pipe.transforms[m].log_columns)
            w = np.concatenate([per_row, np.ones(len(new.objects))])
            X = np.vstack([old.modalities[m], new.modalities[m]])
            np.testing.assert_allclose(pipe.transforms[m].mean_, w @ X / w.sum(), rtol=1e-10)
            checked += 1
    assert checked
    # Relatedness is judged in the prior's space: the decisions at step 0 are "auto"'s.
    for a, lrn in early.learners.items():
        for o, d in lrn.decisions.items():
            assert (d.sources, d.lambdas) == (
                auto.learners[a].decisions[o].sources,
                auto.learners[a].decisions[o].lambdas,
            )
    cfg = LearnerConfig(feature_space="blended")
    assert LearnerConfig.from_dict(cfg.to_dict()) == cfg


def test_fitted_cutoff_keeps_a_transfer_only_when_the_fitted_evidence_favours_it(world):
    """cutoff="fitted": Eq. 3 decides the candidates, then each transfer stays only if the
    fitted transfer model makes the new labels more probable than the classifier fitted without
    the source. With a margin no evidence reaches, every transfer is dropped and the run is the
    baseline's; with one every evidence passes, the run is Eq. 3's (cutoff="paper")."""
    from aptkt.learning.evidence import at_fitted_hyperparameters

    keys = ("mean_accuracy", "fused_accuracy", "action")
    strip = lambda rows: [{k: r[k] for k in keys} for r in rows]  # noqa: E731
    none, run_none = _run(world, transfer="paper", budget=2, cutoff="fitted", evidence_margin=1e9)
    assert all(not d.transfers for lrn in none.learners.values() for d in lrn.decisions.values())
    _, base = _run(world, transfer="none", budget=2)
    assert strip(run_none.rows()) == strip(base.rows())
    _, run_every = _run(world, transfer="paper", budget=2, cutoff="fitted", evidence_margin=-1e9)
    _, run_paper = _run(world, transfer="paper", budget=2, cutoff="paper")
    assert strip(run_every.rows()) == strip(run_paper.rows())
    # At the default margin (0), each recorded log Bayes factor decides the transfer. For a
    # kept one, against an independent route: log p(y | source, θ̂) is the coupled model's log
    # Z minus the source task's own, fitted alone at the classifier's θ̂; the alternative is
    # the new observations' classifier fitted without any source.
    default, _ = _run(world, transfer="paper", budget=0, cutoff="fitted")
    checked = 0
    for lrn in default.learners.values():
        for obj, d in lrn.decisions.items():
            if not d.evidence:
                continue
            ((_, log_bf),) = d.evidence
            assert d.transfers == (log_bf > 0)
            if not d.transfers:
                continue
            model = lrn.model
            k = [str(c) for c in model.classes_].index(obj)
            names = list(model.modality_names_)
            (source,) = model.sources_[obj]
            source_alone = at_fitted_hyperparameters(model, obj).fit(
                source.X, (np.asarray(source.y) > 0).astype(int)
            )
            given_source = (
                model.log_marginal_likelihood_[k] - source_alone.log_marginal_likelihood_[0]
            )
            alone = (
                LearnerConfig()
                .gp.make(dict(zip(names, model.modalities_)), random_state=int(model.random_state))
                .fit(model.X_train_, lrn.observations.objects)
            )
            without = alone.log_marginal_likelihood_[0 if alone.theta_.shape[0] == 1 else k]
            assert log_bf == pytest.approx(given_source - without, abs=1e-6)
            checked += 1
    assert checked
    for bad in (
        dict(transfer="multi"),
        dict(feature_space="covered"),
        dict(feature_space="evidence"),
        dict(gp=GPSettings(latent_mean="base-rate")),
    ):
        with pytest.raises(ValueError, match="fitted|evidence|latent_mean"):
            LearnerConfig(cutoff="fitted", **bad)
    with pytest.raises(ValueError, match="latent_mean"):
        LearnerConfig(feature_space="evidence", gp=GPSettings(latent_mean="base-rate"))


def test_feature_space_shrunk_weighs_the_old_population_by_its_evidence(world):
    """ "shrunk": when the update transfers, each modality's transforms are fitted on the old
    and new observations, the old ones together weighing κ = prior_weight(old, new) — the
    weighted mean against the formula (κ μ_old + Σ x_new) / (κ + n_new)."""
    from aptkt.learning.pipeline import prior_weight

    learner, _ = _run(world, transfer="paper", budget=3, feature_space="shrunk")
    checked = 0
    for a, lrn in learner.learners.items():
        if not any(d.transfers for d in lrn.decisions.values()):
            continue
        assert lrn.space == "shrunk"
        pipe = lrn._test_cache[0]
        old, new = world["prior"][a].observations, lrn.observations
        for m in pipe.modality_names_:
            t = pipe.transforms[m]
            X_old, X_new = t._prepare(old.modalities[m]), t._prepare(new.modalities[m])
            kappa = prior_weight(X_old, X_new)
            assert pipe.prior_weights_[m] == pytest.approx(kappa, rel=1e-12)
            expected = (kappa * X_old.mean(axis=0) + X_new.sum(axis=0)) / (kappa + len(X_new))
            np.testing.assert_allclose(t.mean_, expected, rtol=1e-9, atol=1e-12)
            checked += 1
    assert checked
    cfg = LearnerConfig(feature_space="shrunk")
    assert LearnerConfig.from_dict(cfg.to_dict()) == cfg
