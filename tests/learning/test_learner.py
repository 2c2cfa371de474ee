"""The learner on plain arrays: transfer, auxiliary features, persistence, no simulator."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PoolExhaustedError, PriorKnowledge

from .synthetic import ACTIONS, draw, make_world


@pytest.fixture(scope="module")
def related_world():
    priors, news, means = make_world(
        n_prior=3, n_new=3, noise=1.0, separation=0.6, related=True, seed=1
    )
    return dict(
        news=news,
        prior=PriorKnowledge.build(draw(means, priors, 20, seed=1), seed=0),
        pool=draw(means, news, 30, seed=2),
        test=draw(means, news, 20, seed=3),
    )


def mean_curves(world, transfer, auxiliary=False, seeds=range(4), budget=6):
    curves = []
    for seed in seeds:
        cfg = LearnerConfig(transfer=transfer, auxiliary=auxiliary, budget=budget, seed=seed)
        run = APTKT(cfg, world["prior"]).run(
            PoolEnvironment(world["pool"], seed=seed), list(ACTIONS), world["news"], world["test"]
        )
        curves.append(run.curve()["mean_accuracy"])
    return np.mean(curves, axis=0)


def test_transfer_from_related_priors_beats_the_baseline_early(related_world):
    aptkt = mean_curves(related_world, "paper")
    base = mean_curves(related_world, "none")
    assert aptkt[0] > base[0] + 0.02  # after the initial round: one observation per pair
    assert aptkt[:4].mean() > base[:4].mean() + 0.02


def test_unrelated_priors_do_not_hurt(related_world):
    priors, news, means = make_world(
        n_prior=3, n_new=3, noise=1.0, separation=0.6, related=False, seed=1
    )
    world = dict(
        news=news,
        prior=PriorKnowledge.build(draw(means, priors, 20, seed=1), seed=0),
        pool=draw(means, news, 30, seed=2),
        test=draw(means, news, 20, seed=3),
    )
    aptkt = mean_curves(world, "paper")
    base = mean_curves(world, "none")
    assert np.all(aptkt >= base - 0.05)


def test_transfer_decisions_follow_relatedness(related_world):
    cfg = LearnerConfig(budget=0)
    learner = APTKT(cfg, related_world["prior"])
    run = learner.run(
        PoolEnvironment(related_world["pool"]),
        list(ACTIONS),
        related_world["news"],
        related_world["test"],
    )
    # make_world relates new{j} to old{j}.
    for _action, decisions in run.steps[0].transfer.items():
        for obj, d in decisions.items():
            if d["source"] is not None:
                assert d["source"] == obj.replace("new", "old")
                assert d["lambda"] == pytest.approx(d["mean_posterior"][d["source"]])
                assert d["lambda"] >= cfg.eps_neg


@pytest.mark.parametrize("margin", [-1e9, 1e9])
def test_auxiliary_features_are_an_extra_modality_the_evidence_admits(related_world, margin):
    """Eq. 5: the prior model's posteriors of each observation, in its own feature space, are
    one more modality; the model keeps it only when the new labels' evidence favours it by the
    margin (a margin below any evidence: always; above any: never), its own: the transfer's
    margin is the other extreme."""
    cfg = LearnerConfig(auxiliary=True, budget=1, aux_gate_margin=margin, evidence_margin=-margin)
    learner = APTKT(cfg, related_world["prior"])
    learner.run(
        PoolEnvironment(related_world["pool"]),
        list(ACTIONS),
        related_world["news"],
        related_world["test"],
    )
    lrn = learner.learners["P1"]
    X, groups = lrn._features(lrn.observations, lrn._pipeline())
    assert list(groups) == ["force", "thermal", "auxiliary"]
    n_old = len(related_world["prior"].objects)
    assert len(groups["auxiliary"]) == n_old
    prior = related_world["prior"]["P1"]
    in_prior = prior.pipeline.transform(lrn.observations)[0]
    np.testing.assert_allclose(X[:, groups["auxiliary"]], prior.posteriors(in_prior), atol=1e-12)
    np.testing.assert_allclose(X[:, groups["auxiliary"]].sum(axis=1), 1.0)
    assert lrn.uses_auxiliary == (margin < 0)
    assert np.isfinite(lrn.auxiliary_evidence)
    names = ["force", "thermal"] + (["auxiliary"] if margin < 0 else [])
    assert lrn.model.modality_names_ == names
    np.testing.assert_allclose(lrn.model.X_train_, X[:, : lrn.model.n_features_in_])


def test_without_a_gate_the_auxiliary_features_are_always_used(related_world):
    """The paper's reading (Eq. 5 has no test): the features are a modality of every model,
    and no model without them is fitted to compare."""
    for cfg in (
        LearnerConfig(auxiliary=True, budget=1, aux_gate_margin=None),
        LearnerConfig.paper(auxiliary=True, budget=1),
    ):
        assert cfg.aux_gate_margin is None
        learner = APTKT(cfg, related_world["prior"])
        learner.run(
            PoolEnvironment(related_world["pool"]),
            list(ACTIONS),
            related_world["news"],
            related_world["test"],
        )
        for lrn in learner.learners.values():
            assert lrn.uses_auxiliary and lrn.model.modality_names_[-1] == "auxiliary"
            assert np.isnan(lrn.auxiliary_evidence)


def test_the_auxiliary_gate_margin_is_a_finite_number_or_none():
    assert LearnerConfig().aux_gate_margin == LearnerConfig().evidence_margin == 3.0
    with pytest.raises(ValueError, match="aux_gate_margin"):
        LearnerConfig(aux_gate_margin=float("inf"))


def test_budget_steps_and_reproducibility(related_world):
    cfg = LearnerConfig(budget=5, seed=3)
    runs = [
        APTKT(cfg, related_world["prior"]).run(
            PoolEnvironment(related_world["pool"], seed=3),
            list(ACTIONS),
            related_world["news"],
            related_world["test"],
        )
        for _ in range(2)
    ]
    assert len(runs[0].steps) == 6
    assert runs[0].steps[-1].n_observations == len(ACTIONS) * 3 + 5
    assert [s.action for s in runs[0].steps] == [s.action for s in runs[1].steps]
    np.testing.assert_array_equal(
        runs[0].curve()["mean_accuracy"], runs[1].curve()["mean_accuracy"]
    )


def test_exhausted_pool_stops_the_run(related_world):
    priors, news, means = make_world(seed=5)
    small_pool = draw(means, news, 2, seed=4)
    run = APTKT(LearnerConfig(transfer="none", budget=50)).run(
        PoolEnvironment(small_pool), list(ACTIONS), news
    )
    assert run.stopped_early
    assert run.steps[-1].n_observations == 2 * len(ACTIONS) * len(news)
    env = PoolEnvironment(small_pool)
    env.observe("P1", news[0]), env.observe("P1", news[0])
    with pytest.raises(PoolExhaustedError):
        env.observe("P1", news[0])


def test_configuration_errors():
    with pytest.raises(ValueError, match="eps_neg"):
        LearnerConfig(eps_neg=1.5)
    with pytest.raises(ValueError, match="transfer must be"):
        LearnerConfig(transfer="bold")
    with pytest.raises(ValueError, match="need prior knowledge"):
        APTKT(LearnerConfig(transfer="paper"), prior=None)


def test_prior_knowledge_round_trip(tmp_path, related_world):
    prior = related_world["prior"]
    path = prior.save(tmp_path / "prior.npz")
    with np.load(path, allow_pickle=False) as data:
        assert "meta" in data.files
    loaded = PriorKnowledge.load(path)
    assert loaded.objects == prior.objects and list(loaded.actions) == list(prior.actions)
    for action in prior.actions:
        X = prior[action].training_features()
        np.testing.assert_allclose(loaded[action].training_features(), X)
        np.testing.assert_allclose(
            loaded[action].posteriors(X), prior[action].posteriors(X), rtol=1e-12
        )


def test_learner_runs_on_plain_arrays_without_the_simulator(tmp_path):
    # A fresh interpreter: the learner on a pool of plain arrays must not import aptkt.sim.
    code = textwrap.dedent(
        """
        import sys
        import numpy as np
        from aptkt.learning import APTKT, LearnerConfig, Observations, PoolEnvironment
        rng = np.random.default_rng(0)
        objs = np.repeat(["a", "b", "c"], 10)
        centers = {"a": 0.0, "b": 3.0, "c": 6.0}
        force = np.array([[centers[o] + rng.normal()] for o in objs])
        table = {"press": Observations.from_arrays("press", objs, force=force)}
        run = APTKT(LearnerConfig(transfer="none", budget=3)).run(PoolEnvironment(table), ["press"], ["a", "b", "c"], table)
        assert run.steps[-1].mean_accuracy > 0.6, run.steps[-1].mean_accuracy
        assert not any(m.startswith("aptkt.sim") for m in sys.modules), "the learner imported the simulator"
        print("ok")
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def test_single_modality_models(related_world):
    cfg = LearnerConfig(budget=0, modalities=("thermal",))
    learner = APTKT(cfg, related_world["prior"])
    learner.run(
        PoolEnvironment(related_world["pool"]),
        list(ACTIONS),
        related_world["news"],
        related_world["test"],
    )
    for action in ACTIONS:
        assert learner.learners[action].model.modality_names_ == ["thermal"]
    with pytest.raises(ValueError, match="has none of the modalities"):
        APTKT(LearnerConfig(budget=0, modalities=("force",)), related_world["prior"]).run(
            PoolEnvironment(related_world["pool"]), ["S1"], related_world["news"]
        )
