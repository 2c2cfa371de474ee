"""The learner's own estimate of its accuracy: judgements carried by the 1/n learning curve,
every object weighed once, and the stop at a target accuracy."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from aptkt.learning import APTKT, LearnerConfig, Observations, PoolEnvironment
from aptkt.learning.estimate import AccuracyEstimate


def test_a_judgement_is_carried_to_todays_touches_by_one_over_n():
    est = AccuracyEstimate(["P1"], ["a", "b"])
    counts = {("P1", "a"): 1, ("P1", "b"): 1}
    assert math.isnan(est.value(counts))  # nothing judged yet
    # "a" misjudged at its second touch (1 touch learned), now learned 4 times: error 1·1/4.
    est.judge("P1", "a", 1, recognised=False)
    counts[("P1", "a")] = 4
    # "b" never judged: the mean error of the judged objects.
    assert est.per_action(counts)["P1"] == pytest.approx(1 - 0.25)
    est.judge("P1", "b", 1, recognised=True)
    counts[("P1", "b")] = 2
    assert est.value(counts) == pytest.approx(1 - (0.25 + 0.0) / 2)


def test_every_action_needs_a_judgement_and_counts_once():
    est = AccuracyEstimate(["P1", "S1"], ["a", "b"])
    counts = {(a, o): 2 for a in ("P1", "S1") for o in ("a", "b")}
    est.judge("P1", "a", 1, recognised=False)
    assert math.isnan(est.value(counts))
    est.judge("S1", "b", 1, recognised=True)
    assert est.value(counts) == pytest.approx(np.mean([1 - 0.5, 1 - 0.0]))
    with pytest.raises(ValueError):
        est.judge("P2", "a", 1, recognised=True)
    with pytest.raises(ValueError):
        est.judge("P1", "a", 0, recognised=True)


@given(st.lists(st.tuples(st.integers(1, 30), st.booleans()), min_size=1, max_size=20))
def test_weighing_objects_once_keeps_many_judgements_of_one_object_from_ruling(judged):
    """However often object "a" is judged, the estimate is the mean over the two objects, and
    an object judged right every time counts as error 0."""
    est = AccuracyEstimate(["P1"], ["a", "b"])
    for before, ok in judged:
        est.judge("P1", "a", before, recognised=ok)
    est.judge("P1", "b", 1, recognised=True)
    counts = {("P1", "a"): 31, ("P1", "b"): 2}
    error_a = np.mean([(0.0 if ok else 1.0) * before / 31 for before, ok in judged])
    assert est.value(counts) == pytest.approx(1 - error_a / 2)
    assert 0.5 <= est.value(counts) <= 1.0


def _pool(seed=0):
    rng = np.random.default_rng(seed)
    means = {"a": np.zeros(2), "b": np.array([3.0, 0.0]), "c": np.array([0.0, 3.0])}

    def table(n):
        objs = np.repeat(list(means), n)
        X = np.concatenate([means[o] + rng.normal(size=(n, 2)) for o in means])
        return {"P1": Observations("P1", {"shape": X}, objs)}

    return table(30), table(20)


def test_the_run_stops_once_its_own_estimate_reaches_the_target():
    pool, test = _pool()
    free = APTKT(LearnerConfig(transfer="none", budget=20, seed=0)).run(
        PoolEnvironment(pool, seed=0), ["P1"], ["a", "b", "c"], test=test
    )
    estimates = [s.estimated_accuracy for s in free.steps]
    assert math.isnan(estimates[0]) and all(np.isfinite(estimates[2:]))
    target = max(e for e in estimates if np.isfinite(e))
    first = next(k for k, e in enumerate(estimates) if np.isfinite(e) and e >= target)
    stopped = APTKT(LearnerConfig(transfer="none", budget=20, seed=0, target_accuracy=target)).run(
        PoolEnvironment(pool, seed=0), ["P1"], ["a", "b", "c"], test=test
    )
    assert len(stopped.steps) == first + 1
    assert stopped.stop_reason == "target accuracy" and stopped.stopped_early
    # Up to the stop both runs are the same run.
    assert [s.estimated_accuracy for s in stopped.steps] == estimates[: first + 1]
    with pytest.raises(ValueError, match="target_accuracy"):
        LearnerConfig(target_accuracy=1.5)
