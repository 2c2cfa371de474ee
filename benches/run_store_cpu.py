"""CPU per learning run by class, extrapolated to a whole run store (what `aptkt reproduce`
spends on its learning runs).

Usage: python benches/run_store_cpu.py RUNS_DIR [--per-class 2] [--seed 1] [--out NAME]
                                          [--compare OTHER.json] [--gp NAME=VALUE ...]

RUNS_DIR: the ``runs/`` folder of a run store (each JSON holds a run's spec). Runs are grouped
by (figure, method, number of priors, number of actions); ``--per-class`` of each are drawn at
random (the same ones for the same seed and store), run one after the other in this process
with one BLAS and one core thread (as ``aptkt reproduce`` limits its workers), and their mean
CPU time (``time.process_time``) times the class's size gives its share of the total.
Each run's learning curve (mean and fused test accuracy at every step) is saved with it;
``--compare`` names a result of another build (same store, sampling and seed) and counts the
runs whose curves differ. ``--gp`` changes GP settings of every sampled run (a JSON value,
e.g. ``--gp optimizer_tol=1e-6``), to measure a new default on the store's runs.
"""

from __future__ import annotations

from aptkt.runtime.worker_start import limit_thread_pools

# Before numpy is loaded: OpenBLAS's idle threads spin after every call and would be counted.
limit_thread_pools(1)

import argparse  # noqa: E402
import collections  # noqa: E402
import glob  # noqa: E402
import json  # noqa: E402
import random  # noqa: E402
import time  # noqa: E402

from _common import save  # noqa: E402

from aptkt.experiments.runs import RunSpec, _prior, _table, run_steps  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("runs")
    ap.add_argument("--per-class", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="run_store_cpu")
    ap.add_argument("--compare", help="a result file of another build to compare curves with")
    ap.add_argument("--gp", nargs="*", default=[], metavar="NAME=VALUE")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    gp_changes = {k: json.loads(v) for k, v in (a.split("=", 1) for a in args.gp)}
    classes = collections.defaultdict(list)
    for f in sorted(glob.glob(f"{args.runs}/*.json")):
        s = json.load(open(f))["spec"]
        t = s["tags"]
        key = f"{t.get('figure')}:{s['method']}:{t.get('n_priors')}:{len(s['actions'])}"
        classes[key].append(s)
    out, total, curves = {}, 0.0, {}
    for key, specs in sorted(classes.items()):
        cpu = 0.0
        picked = rng.sample(specs, min(args.per_class, len(specs)))
        for k, s in enumerate(picked):
            if gp_changes:
                s = {**s, "config": {**s["config"], "gp": {**s["config"]["gp"], **gp_changes}}}
            spec = RunSpec.from_dict(s)
            # The observation tables and the prior are loaded once per worker: not timed.
            _table(spec.data, spec.new_objects, spec.pool_trials, spec.actions)
            _table(spec.data, spec.new_objects, spec.test_trials, spec.actions)
            if spec.prior:
                _prior(spec.prior)
            t = time.process_time()
            rows = run_steps(spec)
            cpu += time.process_time() - t
            curves[f"{key}#{k}"] = [[r["mean_accuracy"], r["fused_accuracy"]] for r in rows]
        per_run = cpu / len(picked)
        total += per_run * len(specs)
        out[key] = {"runs": len(specs), "cpu_per_run": per_run, "cpu_total": per_run * len(specs)}
        print(
            f"{key:48s} {len(specs):5d} runs  {per_run:7.2f} CPU-s/run  {per_run * len(specs):7.0f}"
        )
    print(f"total {total:.0f} CPU-s")
    payload = {"args": vars(args), "classes": out, "total": total, "curves": curves}
    if args.compare:
        other = json.load(open(args.compare))["curves"]
        # repr: NaN (a fused accuracy that cannot be formed) equals itself.
        differ = sorted(k for k in curves if repr(other.get(k)) != repr(curves[k]))
        payload["curves_differ"] = differ
        print(
            f"curves: {len(curves) - len(differ)} of {len(curves)} runs identical; differ: {differ}"
        )
    print("saved", save(args.out, payload))


if __name__ == "__main__":
    main()
