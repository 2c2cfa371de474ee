"""The modality-weight hyper-prior, paired on the same single-action runs (issue 11).

Fig. 8's run specs (one action each, 3 priors) are replayed with a shorter budget, once with
flat modality weights (``GPSettings(modality_weight_prior=False)``, the reading before the
prior) and once with the weak prior on the weight logits (the default); everything else —
data, groups, pool orders, exploration draws, the prior files — is the spec's own. (Specs from
a store written with flat weights name prior files built with flat weights, so the comparison
isolates the new objects' models; a full ``aptkt reproduce`` rebuilds the priors as well.) Printed per
action and method: mean test accuracy at every step and over the curve, and the paired
difference (prior − flat) over the curve with a 95 % interval (t, over runs); and the smallest
modality weight of any classifier at step 0 (median over runs).

    python benches/weight_prior.py OUT/fig8/specs.jsonl [--runs 20] [--budget 10] [-j 2]

OUT: the output directory of ``aptkt reproduce`` (its figures' ``specs.jsonl``; the prior files
it names must still be there). The numbers in docs/method.md ("Hyper-parameters") come from
this script.
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy import stats


def _replay(args: tuple) -> tuple[list[float], float]:
    from aptkt.experiments.runs import _prior, _table
    from aptkt.learning import APTKT, PoolEnvironment

    spec, weight_prior, budget = args
    gp = replace(spec.config.gp, modality_weight_prior=weight_prior)
    config = replace(spec.config, budget=budget, gp=gp)
    pool = _table(spec.data, spec.new_objects, spec.pool_trials, spec.actions)
    test = _table(spec.data, spec.new_objects, spec.test_trials, spec.actions)
    learner = APTKT(config, _prior(spec.prior) if config.uses_prior else None)
    smallest: list[float] = []

    def at_step_0(record, learner=learner):
        if record.step == 0:
            for lrn in learner.learners.values():
                for hp in lrn.model.hyperparameters_.values():
                    smallest.append(min(hp["modality_weights"].values()))

    run = learner.run(
        PoolEnvironment(pool, seed=spec.pool_seed),
        spec.actions,
        spec.new_objects,
        test,
        on_step=at_step_0,
    )
    return [s.mean_accuracy for s in run.steps], min(smallest)


def main() -> None:
    from aptkt.experiments.runs import RunSpec

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("specs", type=Path)
    p.add_argument("--runs", type=int, default=20, help="runs per action and method")
    p.add_argument("--budget", type=int, default=10)
    p.add_argument("--methods", default="baseline,APTKT")
    p.add_argument("-j", "--jobs", type=int, default=2)
    args = p.parse_args()

    rows = [json.loads(line) for line in args.specs.open()]
    specs = [RunSpec.from_dict({k: v for k, v in r.items() if k != "key"}) for r in rows]
    methods = args.methods.split(",")
    panels = list(dict.fromkeys(s.tags["panel"] for s in specs))
    chosen = [
        s
        for panel in panels
        for m in methods
        for s in [s for s in specs if s.tags["panel"] == panel and s.method == m][: args.runs]
    ]
    jobs = [(s, w, args.budget) for s in chosen for w in (False, True)]
    with ProcessPoolExecutor(args.jobs) as pool:
        results = list(pool.map(_replay, jobs, chunksize=4))
    flat = {id(s): results[2 * i] for i, s in enumerate(chosen)}
    weak = {id(s): results[2 * i + 1] for i, s in enumerate(chosen)}

    print(f"{args.specs}: {args.runs} runs per action and method, budget {args.budget}")
    print("accuracy at steps 0..budget (flat / weight prior); over the curve; paired difference")
    for panel in panels:
        for m in methods:
            group = [s for s in chosen if s.tags["panel"] == panel and s.method == m]
            if not group:
                continue
            a = np.array([flat[id(s)][0] for s in group])
            b = np.array([weak[id(s)][0] for s in group])
            d = b.mean(1) - a.mean(1)
            half = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
            w_flat = np.median([flat[id(s)][1] for s in group])
            w_weak = np.median([weak[id(s)][1] for s in group])
            print(f"{panel:3s} {m:9s} flat  " + " ".join(f"{v:.3f}" for v in a.mean(0)))
            print(f"{'':3s} {'':9s} prior " + " ".join(f"{v:.3f}" for v in b.mean(0)))
            print(
                f"{'':3s} {'':9s} curve {a.mean():.3f} -> {b.mean():.3f}: "
                f"{100 * d.mean():+.1f} pp [{100 * (d.mean() - half):+.1f}, "
                f"{100 * (d.mean() + half):+.1f}]; smallest weight at step 0 "
                f"{w_flat:.2g} -> {w_weak:.2g}"
            )


if __name__ == "__main__":
    main()
