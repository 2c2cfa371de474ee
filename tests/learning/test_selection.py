"""The choice of the next touch: error reduction touches where the model errs, and touches a
pair less with every touch of it; the paper's rule and random picks stay available."""

from collections import Counter

import numpy as np
import pytest

from aptkt.learning import APTKT, LearnerConfig, Observations, PoolEnvironment


def _world(seed=0):
    """One action, three objects: "a" and "b" overlap (their means one noise level apart),
    "c" lies far from both."""
    rng = np.random.default_rng(seed)
    means = {"a": np.zeros(2), "b": np.array([1.0, 0.0]), "c": np.array([12.0, 12.0])}

    def table(n, offset):
        objs = np.repeat(list(means), n)
        X = np.concatenate([means[o] + rng.normal(size=(n, 2)) for o in means])
        return {
            "P1": Observations("P1", {"shape": X}, objs, trials=np.tile(np.arange(n) + offset, 3))
        }

    return table(30, 0), table(20, 100)


@pytest.mark.parametrize("seed", [0, 1])
def test_each_touch_is_the_pair_of_the_most_error_expected_removed(seed):
    """Before every step, the pair chosen is the one whose model error on its touches so far,
    over their number plus one, is the largest; the step records that score. A pair's score
    falls with every touch of it, so no pair is touched forever."""
    pool, test = _world(seed)
    cfg = LearnerConfig(transfer="none", budget=12, seed=seed)
    learner = APTKT(cfg)
    expected = []

    def before_next(record):
        lrn = learner.learners["P1"]
        scores = {o: lrn.own_error(o) / (lrn.count(o) + 1) for o in ("a", "b", "c")}
        expected.append(max(scores.items(), key=lambda kv: kv[1]))

    run = learner.run(
        PoolEnvironment(pool, seed=seed), ["P1"], ["a", "b", "c"], test=test, on_step=before_next
    )
    for step, (obj, score) in zip(run.steps[1:], expected):
        assert step.object == obj and step.expected_gain == pytest.approx(score)
        assert not step.explored  # error reduction explores by its own score
    picks = Counter(s.object for s in run.steps[1:])
    assert set(picks) == {"a", "b", "c"}


def test_the_paper_rule_and_random_picks_record_no_expected_gain():
    pool, test = _world()
    for selection in ("paper", "random"):
        cfg = LearnerConfig(transfer="none", budget=4, seed=0, selection=selection)
        run = APTKT(cfg).run(PoolEnvironment(pool, seed=0), ["P1"], ["a", "b", "c"], test=test)
        assert all(np.isnan(s.expected_gain) for s in run.steps[1:])
        assert all(np.isfinite(s.uncertainty) for s in run.steps[1:])
        if selection == "random":
            assert all(s.explored for s in run.steps[1:])


def test_the_rules_start_from_the_same_first_round_and_share_the_pool_order():
    """Paired comparisons: whatever the rule, step 0 is the same, and the k-th touch of an
    object reads the same pooled observation."""
    pool, test = _world()
    runs = {
        sel: APTKT(LearnerConfig(transfer="none", budget=6, seed=3, selection=sel)).run(
            PoolEnvironment(pool, seed=3), ["P1"], ["a", "b", "c"], test=test
        )
        for sel in ("error-reduction", "random")
    }
    first = {sel: r.steps[0].mean_accuracy for sel, r in runs.items()}
    assert first["error-reduction"] == first["random"]


def test_the_pools_unused_touches_are_those_not_drawn_yet():
    rng = np.random.default_rng(3)
    objects = np.repeat(["a", "b", "c"], 5)
    obs = Observations("P", {"m": rng.normal(size=(15, 2))}, objects, np.tile(np.arange(5), 3))
    env = PoolEnvironment({"P": obs}, seed=1)
    drawn = [env.observe("P", o)["m"] for o in ("a", "a", "c")]
    unused = env.unused("P")
    assert len(unused) == 12
    assert sorted(unused.objects.tolist()) == sorted(["a"] * 3 + ["b"] * 5 + ["c"] * 4)
    rows = {tuple(r) for r in unused.modalities["m"]}
    assert not rows & {tuple(d) for d in drawn}
    assert rows | {tuple(d) for d in drawn} == {tuple(r) for r in obs.modalities["m"]}
