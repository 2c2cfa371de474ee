"""The stress tests of the cut-off (Fig. 11) live in the reproduction: a learner of their own
(:class:`CutoffStressTest`); the learner's settings offer them no more."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from aptkt.experiments.figures.base import METHODS, STRESS_CUTOFF, STRESS_NO_CUTOFF, Context
from aptkt.experiments.runs import RunSpec
from aptkt.experiments.scale import Scale
from aptkt.experiments.stress import STRESS_FIELDS, CutoffStressTest, with_stress
from aptkt.learning import APTKT, LearnerConfig, Observations, PoolEnvironment, PriorKnowledge


def _observations(means, n, seed):
    rng = np.random.default_rng(seed)
    objects = np.repeat(list(means), n)
    values = np.concatenate([m + 0.5 * rng.normal(size=(n, 2)) for m in means.values()])
    return {"P": Observations("P", {"force": values}, objects)}


def test_the_learners_settings_have_no_stress_test():
    assert not {f.name for f in fields(LearnerConfig)} & set(STRESS_FIELDS)
    with pytest.raises(ValueError, match="forced_lambda"):
        LearnerConfig.from_dict({**LearnerConfig().to_dict(), "forced_lambda": 1.0})


def test_the_stress_methods_are_stress_tests_and_the_others_are_not(tmp_path):
    ctx = Context(
        scale=Scale.quick(),
        seed=0,
        data="d.h5",
        fingerprint="fp",
        output=tmp_path,
        index={},
        base=LearnerConfig.paper(),
    )
    for method in METHODS:
        cfg = ctx.learner(method)
        if method in (STRESS_CUTOFF, STRESS_NO_CUTOFF):
            assert isinstance(cfg, CutoffStressTest)
            assert cfg._transfer_pick() == ("least", 1.0)
            assert cfg.gp == ctx.base.gp  # the reading's kernel, as every method's
        else:
            assert type(cfg) is LearnerConfig and cfg._transfer_pick() == ("most", None)
    assert ctx.learner(STRESS_NO_CUTOFF).cutoff == "paper"


def test_a_stress_test_survives_the_trip_to_a_worker():
    cfg = with_stress(LearnerConfig(budget=2), {"source_choice": "least", "forced_lambda": 1.0})
    spec = RunSpec("s", cfg, "d.h5", ("P1",), ("a",), (0,), (1,))
    back = RunSpec.from_dict(spec.to_dict())
    assert back == spec and isinstance(back.config, CutoffStressTest)
    plain = RunSpec("p", LearnerConfig(), "d.h5", ("P1",), ("a",), (0,), (1,))
    assert type(RunSpec.from_dict(plain.to_dict()).config) is LearnerConfig


@pytest.mark.parametrize(("field", "bad"), [("source_choice", "random"), ("forced_lambda", 1.5)])
def test_a_stress_test_checks_its_settings(field, bad):
    with pytest.raises(ValueError, match=field):
        CutoffStressTest(**{field: bad})


def test_without_a_cut_off_the_stress_test_transfers_the_least_related_at_lambda_one():
    old = {"near": np.zeros(2), "middle": np.array([3.0, 0.0]), "far": np.array([6.0, 0.0])}
    prior = PriorKnowledge.build(_observations(old, 8, seed=1), seed=0)
    pool = _observations({"new0": np.array([0.3, 0.0]), "new1": np.array([5.7, 0.0])}, 4, 2)
    news = ["new0", "new1"]
    cfg = CutoffStressTest(
        budget=0, eps_neg=0.0, cutoff="paper", source_choice="least", forced_lambda=1.0
    )
    learner = APTKT(cfg, prior)
    learner.run(PoolEnvironment(pool, seed=0), ["P"], news)
    for lrn in learner.learners.values():
        for d in lrn.decisions.values():
            assert d.transfers and d.lambdas == (1.0,)
            p_bar = d.as_dict()["mean_posterior"]
            assert d.sources == (min(p_bar, key=p_bar.__getitem__),)
    # The learner's own choice: the most related, at λ = p̄.
    plain = APTKT(LearnerConfig(budget=0, eps_neg=0.0, cutoff="paper"), prior)
    plain.run(PoolEnvironment(pool, seed=0), ["P"], news)
    for lrn in plain.learners.values():
        for d in lrn.decisions.values():
            p_bar = d.as_dict()["mean_posterior"]
            assert d.sources == (max(p_bar, key=p_bar.__getitem__),)
            assert d.lambdas == pytest.approx((p_bar[d.sources[0]],))
