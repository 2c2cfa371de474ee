"""Warm starts of the hyper-parameter search (``LearnerConfig.warm_start``), paired against
the default on the same runs: CPU per run and the accuracy difference.

Usage: python benches/warm_start.py RUNS_DIR [--per-class 20] [--variants previous source]
                                      [--classes fig8:APTKT fig9:APTKT+aux:5 ...] [--seed 1]
                                      [--variant-restarts N]

RUNS_DIR: the ``runs/`` folder of a run store (``aptkt reproduce`` writes one; each JSON holds
a run's spec). Per class (figure, method, number of priors), ``--per-class`` specs are drawn at
random; each is run with the default and with every variant in the same process, one after
the other (CPU by ``time.process_time``). Accuracy: the mean over steps of the mean test
accuracy over actions (the area under the learning curve), and that at the last step; the
paired difference variant − default with a 95 % interval (t, over runs). A variant "off" is
the default's start; ``--variant-restarts`` sets the random restarts of every variant (the
default keeps the runs' own).
"""

from __future__ import annotations

from aptkt.runtime.worker_start import limit_thread_pools

# Before numpy is loaded: OpenBLAS's idle threads spin after every call and would be counted.
limit_thread_pools(1)

import argparse  # noqa: E402
import collections  # noqa: E402
import dataclasses  # noqa: E402
import glob  # noqa: E402
import json  # noqa: E402
import random  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from _common import save  # noqa: E402

from aptkt.experiments.runs import RunSpec, _prior, _table, run_steps  # noqa: E402


def _class_of(spec: dict) -> str:
    t = spec["tags"]
    n = t.get("n_priors")
    return f"{t.get('figure')}:{spec['method']}" + (f":{n}" if n is not None else "")


def _interval(d: np.ndarray) -> tuple[float, float, float]:
    from scipy import stats

    m = float(d.mean())
    if d.size < 2:
        return m, float("nan"), float("nan")
    h = float(stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size))
    return m, m - h, m + h


def _run(spec: RunSpec) -> tuple[float, float, float]:
    t = time.process_time()
    rows = run_steps(spec)
    cpu = time.process_time() - t
    acc = np.array([r["mean_accuracy"] for r in rows])
    return cpu, float(acc.mean()), float(acc[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("runs")
    ap.add_argument("--per-class", type=int, default=20)
    ap.add_argument("--variants", nargs="+", default=["previous", "source"])
    ap.add_argument("--classes", nargs="+", required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="warm_start")
    ap.add_argument("--variant-restarts", type=int, default=None)
    args = ap.parse_args()
    by_class = collections.defaultdict(list)
    for f in sorted(glob.glob(f"{args.runs}/*.json")):
        s = json.load(open(f))["spec"]
        by_class[_class_of(s)].append(s)
    rng = random.Random(args.seed)
    results: dict = {}
    for cls in args.classes:
        specs = rng.sample(by_class[cls], min(args.per_class, len(by_class[cls])))
        rows = []
        for s in specs:
            base = RunSpec.from_dict(s)
            # Load the tables and the prior once, outside the timing.
            _table(base.data, base.new_objects, base.pool_trials, base.actions)
            _table(base.data, base.new_objects, base.test_trials, base.actions)
            if base.prior:
                _prior(base.prior)
            row = {"default": _run(base)}
            for v in args.variants:
                cfg = dataclasses.replace(base.config, warm_start=None if v == "off" else v)
                if args.variant_restarts is not None:
                    gp = dataclasses.replace(cfg.gp, n_restarts=args.variant_restarts)
                    cfg = dataclasses.replace(cfg, gp=gp)
                spec = dataclasses.replace(base, config=cfg)
                row[v] = _run(spec)
            rows.append(row)
            print(cls, {k: tuple(round(x, 3) for x in r) for k, r in row.items()}, flush=True)
        summary = {}
        cpu0 = np.array([r["default"][0] for r in rows])
        for v in args.variants:
            cpu = np.array([r[v][0] for r in rows])
            summary[v] = {
                "runs": len(rows),
                "cpu_default": float(cpu0.sum()),
                "cpu_variant": float(cpu.sum()),
                "cpu_ratio": float(cpu.sum() / cpu0.sum()),
                "auc_diff": _interval(np.array([r[v][1] - r["default"][1] for r in rows])),
                "final_diff": _interval(np.array([r[v][2] - r["default"][2] for r in rows])),
            }
            print(cls, v, json.dumps(summary[v]), flush=True)
        results[cls] = {"summary": summary, "runs": rows}
    print("saved", save(args.out, {"args": vars(args), "results": results}))


if __name__ == "__main__":
    main()
