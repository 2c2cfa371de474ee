"""Does the evidence pick the better feature space? (``LearnerConfig(feature_space="evidence")``)

    python benches/space_choice.py OUT [--figures fig7,fig11]

OUT: a reproduction's output directory (``aptkt reproduce`` or benches/transfer_readings.py).
Its APTKT runs are re-run with ``feature_space="evidence"``; at every update that compares the
two spaces, both candidate models are also scored on the action's test observations (which the
choice never sees). Prints, per figure and for step 0 and the later steps: how many updates
compared the spaces, how often the evidence kept the prior's space, how often the kept model
is the more accurate one (among updates where the two differ in accuracy), and the mean test
accuracy of the kept model, of the prior's, of the new objects' own and of the better one.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from aptkt.experiments.runs import RunSpec, _prior, _table
from aptkt.learning import APTKT, PoolEnvironment
from aptkt.learning.evaluation import accuracy
from aptkt.learning.learner import ActionLearner


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("output", type=Path)
    p.add_argument("--figures", default="fig7,fig11")
    args = p.parse_args()

    scored: dict[tuple[str, int], dict[str, float]] = {}
    compare = ActionLearner._fit_by_evidence
    fit = ActionLearner._fit

    def scoring_fit(self, pipeline, step, X_prior):
        model, X = fit(self, pipeline, step, X_prior)
        if (self.action, step) in scored:  # a comparison of the two spaces
            name = "prior" if pipeline is self.prior.pipeline else "new"
            post = model.predict_proba(self._features(self._test, pipeline)[0])
            scored[(self.action, step)][name] = accuracy(
                post, [str(c) for c in model.classes_], [str(o) for o in self._test.objects]
            )
        return model, X

    def scoring_compare(self, step, X_prior):
        scored[(self.action, step)] = {}
        out = compare(self, step, X_prior)
        scored[(self.action, step)]["kept"] = "prior" if out[0] is self.prior.pipeline else "new"
        return out

    ActionLearner._fit = scoring_fit
    ActionLearner._fit_by_evidence = scoring_compare

    for fig in args.figures.split(","):
        specs = []
        for line in (args.output / fig / "specs.jsonl").read_text().splitlines():
            d = json.loads(line)
            d.pop("key", None)
            specs.append(RunSpec.from_dict(d))
        stats: dict[str, list[tuple[str, float, float]]] = defaultdict(list)
        for spec in specs:
            if spec.method != "APTKT" or spec.tags.get("panel") == "stress":
                continue
            cfg = dataclasses.replace(spec.config, feature_space="evidence")
            pool = _table(spec.data, spec.new_objects, spec.pool_trials, spec.actions)
            test = _table(spec.data, spec.new_objects, spec.test_trials, spec.actions)
            scored.clear()  # keyed by (action, step): one run at a time
            APTKT(cfg, _prior(spec.prior)).run(
                PoolEnvironment(pool, seed=spec.pool_seed), spec.actions, spec.new_objects, test
            )
            for (_, step), s in scored.items():
                if "prior" in s and "new" in s:
                    stats["step 0" if step == 0 else "later"].append(
                        (s["kept"], s["prior"], s["new"])
                    )
        for when, rows in stats.items():
            kept = [r[0] for r in rows]
            prior = np.array([r[1] for r in rows])
            new = np.array([r[2] for r in rows])
            chosen = np.where(np.array(kept) == "prior", prior, new)
            differ = prior != new
            right = np.sum((chosen == np.maximum(prior, new)) & differ)
            print(
                f"{fig} {when:6s}: {len(rows):4d} comparisons, prior's space kept "
                f"{100 * np.mean(np.array(kept) == 'prior'):3.0f} %, the more accurate kept in "
                f"{right} of {int(differ.sum())}; test accuracy kept {chosen.mean():.3f}, "
                f"prior's {prior.mean():.3f}, own {new.mean():.3f}, "
                f"better {np.maximum(prior, new).mean():.3f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
