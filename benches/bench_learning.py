"""Wall time of one full APTKT learning run and where the time goes.

Usage: python benches/bench_learning.py --data FILE [--repeat 3]

FILE: a data set of the simulated world with every paper action on the 3 prior objects
(rough_sponge, paper_box, metal_toolbox) and the 5 new objects, >= 40 trials each, e.g.
    aptkt dataset generate -o sim40.h5 -n 40 -j 2
Trials 0-19 serve as prior knowledge / pool, 20-39 as the test set. The run: 7 actions,
5 new objects, 3 priors, budget 40, APTKT (Eq. 2-3) and, for comparison, the baseline and
APTKT with auxiliary features.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

from _common import save, table

from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge
from aptkt.learning.dataset import load_observations

ACTIONS = ("P1", "P2", "S1", "S2", "S3", "S4", "C1")
PRIORS = ("rough_sponge", "paper_box", "metal_toolbox")
NEW = ("smooth_sponge", "hard_box", "biscuit_box", "mouse_pad", "bamboo_board")

# (label, function qualname fragment) — cumulative time of each in the profile.
PARTS = [
    ("GP fit (Rust, incl. hyper-parameter optimisation)", "gp.py", "fit"),
    ("GP predict_proba (Rust)", "gp.py", "predict_proba"),
    ("feature transforms (scaling, PCA)", "pipeline.py", "transform"),
    ("prior posteriors for transfer/aux", "prior.py", "posteriors"),
    ("transfer decisions (Eq. 3)", "transfer.py", "decide_transfer"),
    ("uncertainty and selection (Eq. 4)", "active.py", "select_next"),
    ("evaluation on the test set", "learner.py", "_record"),
]


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", required=True)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    t0 = time.perf_counter()
    prior_table = load_observations(args.data, actions=ACTIONS, objects=PRIORS, trials=range(20))
    pool = load_observations(args.data, actions=ACTIONS, objects=NEW, trials=range(20))
    test = load_observations(args.data, actions=ACTIONS, objects=NEW, trials=range(20, 40))
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    prior = PriorKnowledge.build(prior_table, seed=0)
    t_prior = time.perf_counter() - t0

    rows = []
    profile_rows = []
    for name, kw in {
        "APTKT": {},
        "baseline": {"transfer": "none"},
        "APTKT+aux": {"auxiliary": True},
    }.items():
        times = []
        for r in range(args.repeat):
            cfg = LearnerConfig(budget=40, seed=r, **kw)
            prof = cProfile.Profile() if (r == 0 and name == "APTKT") else None
            start = time.perf_counter()
            if prof:
                prof.enable()
            run = APTKT(cfg, prior).run(PoolEnvironment(pool, seed=r), ACTIONS, NEW, test)
            if prof:
                prof.disable()
            times.append(time.perf_counter() - start)
            if prof:
                stats = pstats.Stats(prof)
                total = sum(
                    v[3]
                    for k, v in stats.stats.items()
                    if k[2] == "run" and k[0].endswith("learner.py")
                )
                for label, file, func in PARTS:
                    cum = sum(
                        v[3] for k, v in stats.stats.items() if k[0].endswith(file) and k[2] == func
                    )
                    profile_rows.append(
                        {
                            "part": label,
                            "seconds": cum,
                            "share": cum / total if total else float("nan"),
                        }
                    )
        rows.append(
            {
                "method": name,
                "runs": args.repeat,
                "median s (profiled run excluded)": sorted(times[1:] or times)[
                    len(times[1:] or times) // 2
                ],
                "min s": min(times),
                "updates": len(run.steps),
                "final accuracy": run.steps[-1].mean_accuracy,
            }
        )
    print(
        f"loading features: {t_load:.2f} s; building prior knowledge (7 actions): {t_prior:.2f} s"
    )
    print(table(rows, list(rows[0])))
    print(table(profile_rows, ["part", "seconds", "share"]))
    print(
        "saved",
        save(
            "learning",
            {"rows": rows, "profile": profile_rows, "load_s": t_load, "prior_s": t_prior},
        ),
    )


if __name__ == "__main__":
    main()
