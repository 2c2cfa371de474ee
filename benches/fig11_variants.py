"""Fig. 11's APTKT runs re-run with other learner settings, paired with their baselines.

    python benches/fig11_variants.py OUT [KEY=VALUE[,KEY=VALUE...] ...] [--figure fig7]

OUT: a reproduction's output directory (``aptkt reproduce`` or benches/transfer_readings.py)
holding ``fig11/specs.jsonl``. Each argument is one variant: LearnerConfig fields that replace
those of the APTKT runs (e.g. ``transfer=control``, ``feature_space=new``, ``cutoff=paper``;
``-`` for the runs as they are). Prints, per Fig. 11 setting and variant, the mean gain over the
baseline over the curve, at step 0 and at the worst step (pp), and the transfer rate. The
"control" column of docs/experiments.md ("The evidence cut-off") comes from this script.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

from aptkt.experiments.runs import RunSpec, _prior, _table
from aptkt.learning import APTKT, PoolEnvironment

NUMBERS = ("eps_neg", "eps_explor", "evidence_margin")


def _variant(text: str) -> dict:
    if text == "-":
        return {}
    out = {}
    for item in text.split(","):
        key, value = item.split("=", 1)
        out[key] = float(value) if key in NUMBERS else value
    return out


def _accuracies(spec: RunSpec, **override) -> tuple[np.ndarray, int, int]:
    pool = _table(spec.data, spec.new_objects, spec.pool_trials, spec.actions)
    test = _table(spec.data, spec.new_objects, spec.test_trials, spec.actions)
    cfg = dataclasses.replace(spec.config, **override)
    learner = APTKT(cfg, _prior(spec.prior) if spec.prior and cfg.uses_prior else None)
    run = learner.run(
        PoolEnvironment(pool, seed=spec.pool_seed), spec.actions, spec.new_objects, test
    )
    made = [d for s in run.steps for per in s.transfer.values() for d in per.values()]
    taken = sum(1 for d in made if d["sources"])
    return np.array([s.mean_accuracy for s in run.steps]), len(made), taken


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("output", type=Path)
    p.add_argument("variants", nargs="*", default=["-"])
    p.add_argument(
        "--figure", default="fig11", help="whose APTKT runs (e.g. fig7: its one panel, all runs)"
    )
    args = p.parse_args()
    specs = []
    for line in (args.output / args.figure / "specs.jsonl").read_text().splitlines():
        d = json.loads(line)
        d.pop("key", None)
        specs.append(RunSpec.from_dict(d))
    panels = list(dict.fromkeys(s.tags["panel"] for s in specs if s.tags["panel"] != "stress"))
    for panel in panels:
        runs = [s for s in specs if s.tags["panel"] == panel and s.method == "APTKT"]
        for text in args.variants:
            gains, made, taken = [], 0, 0
            for spec in runs:
                (base,) = [b for b in specs if b.tags == spec.tags and b.method == "baseline"]
                acc, m, t = _accuracies(spec, **_variant(text))
                gains.append(acc - _accuracies(base)[0])
                made, taken = made + m, taken + t
            g = 100 * np.mean(gains, axis=0)
            rate = f"{100 * taken / made:3.0f} %" if made else "  —"
            print(
                f"{panel:4s} {text:40s} curve {g.mean():+5.1f}  step 0 {g[0]:+5.1f}  "
                f"worst {g.min():+5.1f}  transfer rate {rate}",
                flush=True,
            )


if __name__ == "__main__":
    main()
