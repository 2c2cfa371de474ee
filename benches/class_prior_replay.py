"""Replay recorded runs and score each step's models with both class priors (issue 11).

The runs are repeated as recorded (``class_prior="training"``, the default, decides and
selects); at every step the same models' test posteriors are also formed with the base rates
set to 1/K (``aptkt.gp.uniform_class_prior``), so the two accuracies differ by the class
prior alone. Also printed: the share of test predictions that go to the most-observed object.

    python benches/class_prior_replay.py OUT/fig8/specs.jsonl --panel S1 --method baseline \\
        --runs 10 --budget 8

OUT: the output directory of ``aptkt reproduce`` (its figures' ``specs.jsonl``). The numbers in
docs/experiments.md ("The class posterior") come from this script.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import numpy as np


def main() -> None:
    from aptkt.experiments.runs import RunSpec, _prior, _table
    from aptkt.gp import uniform_class_prior
    from aptkt.learning import APTKT, PoolEnvironment

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("specs", type=Path)
    p.add_argument("--panel", required=True)
    p.add_argument("--method", default="baseline")
    p.add_argument("--runs", type=int, default=10)
    p.add_argument("--budget", type=int, default=8)
    args = p.parse_args()

    rows = [json.loads(line) for line in args.specs.open()]
    specs = [RunSpec.from_dict({k: v for k, v in r.items() if k != "key"}) for r in rows]
    specs = [s for s in specs if s.tags.get("panel") == args.panel and s.method == args.method]
    if not specs:
        raise SystemExit(f"no {args.method} runs of panel {args.panel} in {args.specs}")
    training, uniform, top_share = defaultdict(list), defaultdict(list), defaultdict(list)
    for spec in specs[: args.runs]:
        if spec.config.gp.class_prior != "training":
            raise SystemExit("replay runs recorded with the default class_prior='training'")
        pool = _table(spec.data, spec.new_objects, spec.pool_trials, spec.actions)
        test = _table(spec.data, spec.new_objects, spec.test_trials, spec.actions)
        config = replace(spec.config, budget=args.budget)
        learner = APTKT(config, _prior(spec.prior) if config.uses_prior else None)

        def score(record, learner=learner, test=test, spec=spec):
            for action in spec.actions:
                lrn = learner.learners[action]
                classes = np.array([str(c) for c in lrn.model.classes_])
                truth = np.array([str(o) for o in test[action].objects])
                binary = lrn.model.predict_proba_binary(lrn._test_cache[1])
                adjusted = uniform_class_prior(binary, lrn.model.base_rates_)
                training[record.step].append(lrn.test_accuracy())
                uniform[record.step].append(float(np.mean(classes[adjusted.argmax(1)] == truth)))
                most = classes[np.argmax(lrn.model.class_counts_)]
                top_share[record.step].append(
                    float(np.mean(classes[lrn.test_posteriors.argmax(1)] == most))
                )

        learner.run(
            PoolEnvironment(pool, seed=spec.pool_seed),
            spec.actions,
            spec.new_objects,
            test,
            on_step=score,
        )
    n = min(args.runs, len(specs))
    print(f"{args.method} {args.panel}, {n} runs: step, accuracy training / uniform, ")
    print("share of test predictions to the most-observed object (training)")
    for step in sorted(training):
        print(
            f"{step:3d}  {np.mean(training[step]):.3f} / {np.mean(uniform[step]):.3f}  "
            f"{np.mean(top_share[step]):.2f}"
        )


if __name__ == "__main__":
    main()
