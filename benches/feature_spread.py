"""How far apart the new objects lie in each feature space of the learner, for one Fig. 11
setting (docs/experiments.md, "The pooled feature space").

    python benches/feature_spread.py OUT SETTING [--per-object 1 3]

OUT: a reproduction's output directory holding ``fig11/specs.jsonl`` (``aptkt reproduce`` or
benches/transfer_readings.py). Takes the setting's first APTKT run (its dissimilar priors, new
objects and pool) and draws ``k`` training observations per new object from the pool. For the
prior's space, the pooled one (old and training observations together) and the baseline's one
(training observations only) it prints, per modality, the spread of the new objects' class means
(root-mean-square distance from their centre, over all pool observations) and the mean
within-object standard deviation per column.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from aptkt.experiments.runs import RunSpec, _prior, _table
from aptkt.learning import FeaturePipeline
from aptkt.learning.observations import Observations


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("output", type=Path)
    p.add_argument("setting")
    p.add_argument("--per-object", type=int, nargs="+", default=[1, 3])
    args = p.parse_args()
    lines = (args.output / "fig11" / "specs.jsonl").read_text().splitlines()
    specs = [
        RunSpec.from_dict({k: v for k, v in json.loads(t).items() if k != "key"}) for t in lines
    ]
    spec = next(s for s in specs if s.tags.get("panel") == args.setting and s.method == "APTKT")
    assert spec.prior is not None  # APTKT runs carry their prior
    pool = _table(spec.data, spec.new_objects, spec.pool_trials, spec.actions)
    prior = _prior(spec.prior)
    rng = np.random.default_rng(0)
    for a in spec.actions:
        everything, old = pool[a], prior[a].observations
        for k in args.per_object:
            idx = np.concatenate(
                [
                    rng.choice(np.flatnonzero(everything.objects == o), k, replace=False)
                    for o in spec.new_objects
                ]
            )
            train = Observations(
                a,
                {m: v[idx] for m, v in everything.modalities.items()},
                everything.objects[idx],
                everything.trials[idx],
            )
            spaces = {
                "prior": prior[a].pipeline,
                "pooled": FeaturePipeline().fit(Observations.concat([old, train])),
                "new": FeaturePipeline().fit(train),
            }
            for name, pipe in spaces.items():
                X, groups = pipe.transform(everything)
                parts = []
                for m, cols in groups.items():
                    per = [X[everything.objects == o][:, cols] for o in spec.new_objects]
                    means = np.array([x.mean(axis=0) for x in per])
                    between = np.sqrt(((means - means.mean(axis=0)) ** 2).sum(axis=1).mean())
                    within = np.mean([x.std(axis=0).mean() for x in per])
                    parts.append(f"{m} between {between:.2f} within {within:.2f}")
                print(
                    f"{a} {k}/object, {len(old)} old: {name:6s} " + " | ".join(parts),
                    flush=True,
                )


if __name__ == "__main__":
    main()
