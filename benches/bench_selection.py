"""What choosing the next touch costs: error reduction against AT-LPP (Eq. 4), side by side.

Usage: python benches/bench_selection.py --data FILE [--rounds 200]

FILE: a data set of the simulated world with every paper action on the 3 prior objects
(rough_sponge, paper_box, metal_toolbox) and the 5 new objects, >= 12 trials each, e.g.
    aptkt dataset generate -o sim12.h5 -n 12 -j 2
Trials 0-5 are the prior knowledge and the pool, 6-11 the test set. An APTKT run with 7 actions
and 5 new objects (35 pairs) spends a budget of 20; at its end one decision of each rule is
timed from the same models, interleaved in rounds (the median CPU time of each, and the median
of their per-round ratio), and so is what every touch adds besides: judging it before it is
learned and the learner's own estimate of its accuracy.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from _common import save, table

from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge
from aptkt.learning.active import select_next
from aptkt.learning.dataset import load_observations
from aptkt.learning.estimate import AccuracyEstimate

ACTIONS = ("P1", "P2", "S1", "S2", "S3", "S4", "C1")
PRIORS = ("rough_sponge", "paper_box", "metal_toolbox")
NEW = ("smooth_sponge", "hard_box", "biscuit_box", "mouse_pad", "bamboo_board")


def cpu(fn) -> float:
    start = time.process_time()
    fn()
    return time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", required=True)
    parser.add_argument("--rounds", type=int, default=200)
    args = parser.parse_args()
    prior_table = load_observations(args.data, actions=ACTIONS, objects=PRIORS, trials=range(6))
    pool = load_observations(args.data, actions=ACTIONS, objects=NEW, trials=range(6))
    test = load_observations(args.data, actions=ACTIONS, objects=NEW, trials=range(6, 12))
    prior = PriorKnowledge.build(prior_table, seed=0)
    learner = APTKT(LearnerConfig(budget=20, seed=0), prior)
    run = learner.run(PoolEnvironment(pool, seed=0), ACTIONS, NEW, test)
    rng = np.random.default_rng(0)
    pairs = [(a, o) for a in ACTIONS for o in NEW]

    def decide(rule: str, eps: float):
        return lambda: select_next(learner.pair_scores(rule), ACTIONS, NEW, eps, rng, pairs)

    estimate = AccuracyEstimate(ACTIONS, NEW)
    for step in run.steps[1:]:
        estimate.judge(step.action, step.object, 1, bool(step.touch_recognised))
    touch = pool["S1"].row(0)
    counts = {(a, o): learner.learners[a].count(o) for a, o in pairs}

    def judge_and_estimate():
        learner.learners["S1"].judge("hard_box", touch)
        estimate.value(counts)

    paper, ours, extra, ratios = [], [], [], []
    for _ in range(args.rounds):
        p = cpu(decide("paper", 0.1))
        e = cpu(decide("error-reduction", 0.0))
        paper.append(p)
        ours.append(e)
        extra.append(cpu(judge_and_estimate))
        if p > 0:
            ratios.append(e / p)
    rows = [
        ["AT-LPP decision (Eq. 4), 35 pairs", f"{1e3 * statistics.median(paper):.3f} ms"],
        ["error-reduction decision, 35 pairs", f"{1e3 * statistics.median(ours):.3f} ms"],
        ["ratio error reduction / AT-LPP (median per round)", f"{statistics.median(ratios):.2f}"],
        ["judging a touch + the own estimate", f"{1e3 * statistics.median(extra):.3f} ms"],
        ["whole run (7 actions, budget 20), wall", f"{sum(s.seconds for s in run.steps):.2f} s"],
    ]
    print(table([{"what": w, "median": v} for w, v in rows], ["what", "median"]))
    save(
        "selection",
        {
            "rounds": args.rounds,
            "paper_ms": 1e3 * statistics.median(paper),
            "error_reduction_ms": 1e3 * statistics.median(ours),
            "ratio": statistics.median(ratios),
            "judge_and_estimate_ms": 1e3 * statistics.median(extra),
        },
    )


if __name__ == "__main__":
    main()
