"""Transfer decisions in words: the old object learned from with λ, or which cut-off stopped
the transfer and why, for one decision and over runs."""

from __future__ import annotations

import numpy as np

from aptkt.learning import LearnerConfig, decide_transfer
from aptkt.learning.transfer_summary import (
    BELOW_EPS_NEG,
    EVIDENCE_CUTOFF,
    TRANSFERS,
    describe,
    describe_runs,
    final_decisions,
    summary_lines,
    verdict,
)

OLD = ["foam", "cardboard", "steel"]
CONFIG = LearnerConfig(cutoff="evidence")  # eps_neg 0.5, the evidence cut-off with margin 3


def _decision(p, log_bf=None, new="sponge", config=CONFIG):
    """The learner's own rule (Eq. 3, then the evidence) on posteriors whose mean is ``p``."""
    evidence = None if log_bf is None else (lambda old, lam: log_bf)
    return decide_transfer(
        new,
        OLD,
        np.array([p, p]),
        config.eps_neg,
        evidence=evidence,
        evidence_margin=config.evidence_margin,
    ).as_dict()


def test_a_transfer_names_the_old_object_lambda_and_evidence():
    d = _decision([0.8, 0.1, 0.1], log_bf=5.2)
    v = verdict(d, CONFIG)
    assert (v.outcome, v.candidate, v.lam, v.log_bf) == (TRANSFERS, "foam", 0.8, 5.2)
    assert describe(d, CONFIG) == "sponge <- foam (lambda 0.80, log BF 5.2 > 3)"


def test_the_evidence_cut_off_says_so_with_its_log_bayes_factor():
    d = _decision([0.1, 0.84, 0.2], log_bf=1.8)
    assert verdict(d, CONFIG).outcome == EVIDENCE_CUTOFF
    assert describe(d, CONFIG) == (
        "sponge: no transfer, most like cardboard (p 0.84) but log BF 1.8 <= 3 (evidence cut-off)"
    )


def test_the_same_object_cut_off_says_so_with_its_log_odds():
    """The default cut-off: the library's log odds that the new object is the old one."""
    config = LearnerConfig()
    d = _decision([0.8, 0.2, 0.1], log_bf=6.4, config=config)
    assert describe(d, config) == "sponge <- foam (lambda 0.80, log odds 6.4 > 3)"
    d = _decision([0.3, 0.84, 0.1], log_bf=-2.0, config=config)
    assert describe(d, config) == (
        "sponge: no transfer, most like cardboard (p 0.84) but log odds -2.0 <= 3 "
        "(same-object cut-off)"
    )


def test_eps_neg_says_so_and_never_rounds_up_to_the_limit():
    d = _decision([0.4996, 0.2, 0.1], log_bf=10.0)  # never tested: below eps_neg
    assert verdict(d, CONFIG).outcome == BELOW_EPS_NEG and d["log_bayes_factor"] == {}
    assert describe(d, CONFIG) == "sponge: no transfer, most like foam (p 0.4996 < eps_neg 0.5)"


def test_the_papers_cut_off_transfers_without_a_bayes_factor():
    config = LearnerConfig(cutoff="paper")
    d = _decision([0.2, 0.1, 0.7], config=config)
    assert describe(d, config) == "sponge <- steel (lambda 0.70)"


def test_runs_that_agree_are_told_once_with_their_means_and_count():
    runs = [
        _decision([0.8, 0.1, 0.1], log_bf=4.0),
        _decision([0.6, 0.1, 0.1], log_bf=6.0),
        _decision([0.7, 0.1, 0.1], log_bf=1.0),
    ]
    assert describe_runs(runs, CONFIG) == (
        "sponge <- foam (lambda 0.70, log BF 5.0 > 3) in 2/3 runs; "
        "no transfer, most like foam (p 0.70) but log BF 1.0 <= 3 (evidence cut-off) in 1/3 runs"
    )


def test_the_final_decision_of_each_pair_is_the_last_one_made():
    first = {
        "P2": {
            "sponge": _decision([0.8, 0.1, 0.1], 5.0),
            "box": _decision([0.1, 0.3, 0.2], new="box"),
        }
    }
    later = {"P2": {"sponge": _decision([0.1, 0.8, 0.1], 1.0)}}  # only sponge's model updated
    final = final_decisions([first, later])
    assert final["P2"]["box"] is first["P2"]["box"]
    assert final["P2"]["sponge"] is later["P2"]["sponge"]
    lines = summary_lines([final, final], CONFIG)
    assert lines[0].startswith("P2  sponge: no transfer, most like cardboard")
    assert lines[0].endswith("in 2/2 runs")
    assert lines[1].startswith("    box: no transfer, most like cardboard (p 0.30 < eps_neg 0.5)")
