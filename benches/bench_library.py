"""Where a learning run's time goes as the library grows, and what the "library" kernel saves.

Usage: python benches/bench_library.py [--table TABLE] [--sizes 3,5,10,15,30] [--budget 10]

Without --table, a synthetic library in the shape of the BioTac benchmark's (27 columns in 4
modalities, 12 observations per object, objects 2.5 noise levels apart); with a feature table
of one action (e.g. the BioTac import), its objects (the first half of their trials). For each
library size, one learning run of 5 new objects with the control (the prior's space, no
transfer — so that both kernels do the same work apart from the kernel), CPU seconds
(``time.process_time``, one thread):

* ``library``: the default kernel — σ² from the number of new objects, the length-scale from the
  library's evidence (computed once per library: "curve") plus the new objects' at each update;
* ``shared``: the kernel learned on the old and new observations together, refitted at every
  update (the default until 2026-11-27), its peer.

The ratio shared/library per update is the saving; "curve" and "prior" are one-off costs.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from _common import save, table

os.environ.setdefault("RAYON_NUM_THREADS", "1")

from aptkt.learning import APTKT, GPSettings, LearnerConfig, PoolEnvironment, PriorKnowledge  # noqa: E402
from aptkt.learning.observations import Observations  # noqa: E402

GROUPS = {"a": 3, "b": 2, "c": 3, "d": 19}


def synthetic(n_objects: int, n_per: int, seed: int) -> Observations:
    rng = np.random.default_rng(seed)
    d = sum(GROUPS.values())
    means = rng.normal(scale=2.5, size=(n_objects, d))
    X = np.concatenate([m + rng.normal(size=(n_per, d)) for m in means])
    objects = np.repeat([f"o{seed}_{k}" for k in range(n_objects)], n_per)
    mods, start = {}, 0
    for m, width in GROUPS.items():
        mods[m] = X[:, start : start + width]
        start += width
    return Observations("A", mods, objects, np.tile(np.arange(n_per), n_objects))


def from_table(path: str) -> tuple[Observations, list[str]]:
    from aptkt.experiments.benchmark import split_trials
    from aptkt.learning.feature_table import read_feature_table

    t = read_feature_table(path)
    action = t.action_names[0]
    learn, _ = split_trials(t, [action])
    obs = t.observations([action], learn)[action]
    return obs, [str(o) for o in t.object_names]


def cpu(fn):
    t0 = time.process_time()
    out = fn()
    return out, time.process_time() - t0


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--table", help="a feature table of one action (default: synthetic)")
    parser.add_argument("--sizes", default="3,5,10,15,30")
    parser.add_argument("--budget", type=int, default=10)
    args = parser.parse_args()
    sizes = [int(k) for k in args.sizes.split(",")]
    if args.table:
        obs, names = from_table(args.table)
        new_names, old_names = names[:5], names[5:]
        sizes = [k for k in sizes if k <= len(old_names)]
        new = obs.of_objects(new_names)
    else:
        new_names = [f"o999_{k}" for k in range(5)]
        new = synthetic(5, 12, 999)
    rows = []
    for k in sizes:
        old = obs.of_objects(old_names[:k]) if args.table else synthetic(k, 12, k)
        pool = {"A": new}
        row: dict[str, object] = {"priors": k, "old rows": len(old)}
        for kernel in ("library", "shared"):
            gp = GPSettings(kernel=kernel)
            prior, t_prior = cpu(
                lambda gp=gp, old=old: PriorKnowledge.build({"A": old}, gp=gp, seed=0)
            )
            cfg = LearnerConfig(transfer="control", budget=args.budget, seed=0, gp=gp)
            learner = APTKT(cfg, prior)
            t0 = time.process_time()
            run = learner.run(PoolEnvironment(pool, seed=0), ["A"], new_names)
            total = time.process_time() - t0
            per_update = [s.seconds for s in run.steps[1:]]
            row[f"{kernel}: prior (s)"] = round(t_prior, 2)
            row[f"{kernel}: run (CPU s)"] = round(total, 2)
            row[f"{kernel}: step 0 (s)"] = round(run.steps[0].seconds, 3)
            row[f"{kernel}: per update (s)"] = round(float(np.median(per_update)), 4)
        row["shared / library per update"] = round(
            float(row["shared: per update (s)"]) / max(float(row["library: per update (s)"]), 1e-9),
            1,
        )
        rows.append(row)
        print(row, flush=True)
    columns = list(rows[0])
    print(table(rows, columns))
    path = save(
        "library", {"table": args.table or "synthetic", "budget": args.budget, "rows": rows}
    )
    print(path)


if __name__ == "__main__":
    main()
