"""Aggregation of per-step rows into curves, paired gains and intervals, on hand-made results."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aptkt.experiments.aggregate import (
    Curves,
    collect,
    difference,
    estimate,
    mean_over_panels,
    t_quantile,
)
from aptkt.experiments.figures.common import (
    error_removed,
    gain_summary,
    mean_lambda,
    prior_space_rate,
    share_text,
    transfer_rate,
)


def rows_from(matrix, method="m", start_group=0, trials_per_group=2, **tags):
    """One row per (run, step); run r is (group r // trials_per_group, trial r % trials_per_group)."""
    out = []
    for r, values in enumerate(matrix):
        for step, v in enumerate(values):
            if v is None:
                continue  # the run has no such step (stopped early)
            out.append(
                {
                    "method": method,
                    "group": start_group + r // trials_per_group,
                    "run": r % trials_per_group,
                    "step": step,
                    "mean_accuracy": v,
                    **tags,
                }
            )
    return out


def test_means_spreads_and_counts_by_hand():
    rows = rows_from([[0.5, 0.6, 0.7], [0.3, 0.4, None], [0.4, 0.8, 0.9]])
    c = collect(rows)
    assert c.runs == [(0, 0), (0, 1), (1, 0)]
    assert c.x.tolist() == [0, 1, 2]
    np.testing.assert_allclose(c.mean(), [0.4, 0.6, 0.8])
    # Population standard deviation (ddof 0), as the plots' bands; the missing step is skipped.
    np.testing.assert_allclose(c.sd(), [math.sqrt(0.02 / 3), math.sqrt(0.08 / 3), 0.1])
    assert c.count().tolist() == [3, 3, 2]
    np.testing.assert_allclose(c.run_means(), [0.6, 0.35, 0.7])
    assert np.isnan(c.values[1, 2])


def test_filtering_and_bookkeeping_errors():
    rows = rows_from([[0.1, 0.2]], method="a", panel="P1") + rows_from(
        [[0.9, 0.8]], method="b", panel="P1"
    )
    assert collect(rows, {"method": "b"}).values.tolist() == [[0.9, 0.8]]
    assert collect(rows, {"method": ("a", "b")}, run_by=("method", "group", "run")).n_runs == 2
    with pytest.raises(ValueError, match="two rows at step"):
        collect(rows)  # two methods under one run identity: a bookkeeping error, never averaged
    with pytest.raises(LookupError):
        collect(rows, {"method": "c"})
    with pytest.raises(KeyError, match="group"):
        collect([{"step": 0, "mean_accuracy": 1.0}])


def test_difference_pairs_runs_whatever_their_order():
    a = collect(rows_from([[0.5, 0.7], [0.6, 0.9], [0.2, 0.2]]))
    shuffled = rows_from([[0.4, 0.5], [0.5, 0.5]])
    random.Random(1).shuffle(shuffled)
    b = collect(shuffled)
    d = difference(a, b)  # the third run of a has no partner and is left out
    assert d.runs == [(0, 0), (0, 1)]
    np.testing.assert_allclose(d.values, [[0.1, 0.2], [0.1, 0.4]])
    with pytest.raises(ValueError, match="x axes"):
        difference(a, collect(rows_from([[0.1, 0.2, 0.3]])))


def test_estimate_over_groups_and_over_runs():
    # Two groups of two runs: the interval is over the group means (0.1 and 0.3).
    e = estimate([0.0, 0.2, 0.2, 0.4], units=[0, 0, 1, 1])
    assert (e.n, e.unit) == (2, "groups")
    half = 12.706 * np.std([0.1, 0.3], ddof=1) / math.sqrt(2)
    assert e.mean == pytest.approx(0.2)
    assert (e.low, e.high) == (pytest.approx(0.2 - half), pytest.approx(0.2 + half))
    # One group: over the runs.
    e = estimate([0.1, 0.2, 0.3], units=[5, 5, 5])
    assert (e.n, e.unit) == (3, "runs")
    assert e.high - e.mean == pytest.approx(4.303 * 0.1 / math.sqrt(3))
    single = estimate([0.4])
    assert single.mean == 0.4 and math.isnan(single.low)
    assert estimate([float("nan")]).n == 0


def test_t_quantile_against_scipy():
    from scipy import stats  # a scikit-learn dependency, so always there when the suite runs

    for df in (1, 2, 5, 9, 19, 22, 33, 49, 75, 200, 10_000):
        assert t_quantile(df) == pytest.approx(stats.t.ppf(0.975, df), abs=2e-3)


def test_mean_over_panels_per_run():
    p1 = collect(rows_from([[0.2, 0.4], [0.6, 0.8]]))
    p2 = collect(rows_from([[0.4, 0.6], [0.0, 1.0]]))
    avg = mean_over_panels([p1, p2])
    np.testing.assert_allclose(avg.values, [[0.3, 0.5], [0.3, 0.9]])
    with pytest.raises(ValueError):
        mean_over_panels([p1, collect(rows_from([[0.1, 0.1]]))])


def test_gain_summary_by_hand():
    base = collect(rows_from([[0.5, 0.5, 0.5]] * 4))
    # Gains per run: group 0 runs +0.1, +0.3 at every step; group 1: -0.1 at step 0, then +0.2.
    aptkt = collect(rows_from([[0.6, 0.6, 0.6], [0.8, 0.8, 0.8], [0.4, 0.7, 0.7], [0.4, 0.7, 0.7]]))
    s = gain_summary({"baseline": base, "APTKT": aptkt}, "APTKT", steps=[0, 2])
    assert s.overall.mean == pytest.approx((0.2 + 0.1) / 2)  # group means of the run means
    assert s.at[0].mean == pytest.approx((0.2 - 0.1) / 2)
    assert s.peak_step in (1, 2) and s.peak.mean == pytest.approx(0.2)
    assert s.positive_steps == 1.0


def test_transfer_rate_counts_decisions():
    rows = [
        {"method": "APTKT", "decisions": 35, "transfers": 7},
        {"method": "APTKT", "decisions": 5, "transfers": 5},
        {"method": "baseline", "decisions": 0, "transfers": 0},
    ]
    assert transfer_rate(rows, {"method": "APTKT"}) == pytest.approx(12 / 40)
    assert math.isnan(transfer_rate(rows, {"method": "baseline"}))


def test_prior_space_share_of_runs_stored_before_it_was_recorded_says_so():
    rows = [
        {"method": "APTKT", "updates": 8, "prior_space": 6},
        {"method": "APTKT", "updates": 2, "prior_space": 0},
        {"method": "old APTKT"},  # a run stored before the counts existed
    ]
    assert share_text(prior_space_rate(rows, {"method": "APTKT"})) == "60 %"
    assert share_text(prior_space_rate(rows, {"method": "APTKT"}), 1) == "60.0 %"
    assert share_text(prior_space_rate(rows, {"method": "old APTKT"})) == "not recorded"


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.integers(1, 7), st.integers(0, 2**31 - 1))
def test_collect_recovers_any_matrix(n_runs, n_steps, seed):
    rng = np.random.default_rng(seed)
    m = rng.uniform(size=(n_runs, n_steps))
    rows = rows_from(m.tolist(), trials_per_group=3)
    random.Random(seed).shuffle(rows)
    c = collect(rows)
    np.testing.assert_array_equal(c.values, m)
    np.testing.assert_allclose(c.mean(), m.mean(axis=0))
    np.testing.assert_allclose(c.sd(), m.std(axis=0))
    assert isinstance(c, Curves)


def test_mean_band_is_the_t_interval_of_the_mean():
    """The plots' bands: 95 % Student-t interval of the mean over runs, per column (scipy as
    the independent reference); columns with fewer than two runs have no band."""
    from scipy import stats

    from aptkt.experiments.aggregate import mean_band

    rng = np.random.default_rng(1)
    values = rng.uniform(0.2, 0.9, size=(7, 4))
    values[2:, 3] = np.nan  # two runs left in the last column
    values[1:, 0] = np.nan  # one run in the first
    mean, low, high = mean_band(values)
    for j in (1, 2, 3):
        v = values[np.isfinite(values[:, j]), j]
        lo, hi = stats.t.interval(0.95, len(v) - 1, loc=v.mean(), scale=stats.sem(v))
        assert mean[j] == pytest.approx(v.mean())
        assert low[j] == pytest.approx(lo, abs=2e-3) and high[j] == pytest.approx(hi, abs=2e-3)
    assert mean[0] == pytest.approx(values[0, 0]) and np.isnan(low[0]) and np.isnan(high[0])


def test_error_removed_reads_a_gain_against_the_baselines_room():
    # Two runs per method; baseline means 0.5, 0.8 at steps 0, 1; APTKT 0.7, 0.9.
    base = collect(rows_from([[0.4, 0.7], [0.6, 0.9]], method="baseline"), {"method": "baseline"})
    aptkt = collect(rows_from([[0.6, 0.8], [0.8, 1.0]], method="APTKT"), {"method": "APTKT"})
    gain = difference(aptkt, base)
    acc, share = error_removed(base, gain, step=0)
    assert acc == pytest.approx(0.5) and share == pytest.approx(0.2 / 0.5)
    acc, share = error_removed(base, gain, step=1)
    assert acc == pytest.approx(0.8) and share == pytest.approx(0.1 / 0.2)
    # Over the curve: mean accuracies 0.65 and 0.8, so 0.15 of the 0.35 left.
    acc, share = error_removed(base, gain)
    assert acc == pytest.approx(0.65) and share == pytest.approx(0.15 / 0.35)
    # A perfect baseline leaves no room: no share, not a division by zero.
    perfect = collect(rows_from([[1.0, 1.0]], method="baseline"), {"method": "baseline"})
    assert math.isnan(error_removed(perfect, difference(perfect, perfect))[1])


def test_mean_lambda_weighs_each_row_by_its_sources():
    rows = [
        {"method": "APTKT", "sources": 3, "mean_lambda": 0.9},
        {"method": "APTKT", "sources": 1, "mean_lambda": 0.5},
        {"method": "APTKT", "sources": 0, "mean_lambda": float("nan")},
        {"method": "baseline", "sources": 0, "mean_lambda": float("nan")},
    ]
    assert mean_lambda(rows, {"method": "APTKT"}) == pytest.approx((3 * 0.9 + 0.5) / 4)
    assert math.isnan(mean_lambda(rows, {"method": "baseline"}))
