"""What a library costs as it grows, from 15 objects to 10,000: building it, learning new
objects with it, recognising a touch, merging new objects into it — CPU seconds and peak
memory, the default (local) library model beside the exact one wherever the exact one can
still run.

Usage:
    python benches/bench_library_scale.py [--sizes 15,30,100,300,1000,3000,10000]
        [--exact-up-to 100] [--from TABLE] [--dask-at 10000] [--plot PATH]

A synthetic library in the issue's shape: one action of 12 columns (two modalities, 8 + 4),
25 trials per object of which the first 12 are the library's and the pool of new objects
(the rest held out). Its objects are drawn from a population (aptkt.experiments.population):
by default a Gaussian one whose objects one observation tells apart as often as the BioTac
set's (0.85 among 20); with --from TABLE, the population fitted on that table's first action
(its columns, not 12).

Each size and model runs in a fresh process, so that its peak memory (ru_maxrss) is its own.
CPU seconds count every thread of the process (user + system), so a loaded machine changes
them little. Per size:

* build: PriorKnowledge.build and the calibrations a library file carries (precompute), as
  ``aptkt prior build`` does; with --dask-at N, the build of N objects again with the
  calibrations on a local Dask cluster of 2 workers (their peak memory reported);
* learn: APTKT learning 5 new objects, budget 20, all-in; the slowest update (wall time of a
  step, on an otherwise quiet machine the same as its CPU time) and the median;
* recognise: one touch, the mean over 500 touches (the library's calibration as saved);
* merge: the library and a library of the 5 learned objects, refitted and calibrated.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import resource
import sys
import time

import numpy as np
from _common import RESULTS, save, table

STREAMS = {"library": 1, "new": 2}


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def population(path: str | None):
    from aptkt.experiments.population import ActionPopulation, ObjectPopulation, _matching_spread

    if path:
        from aptkt.learning.feature_table import read_feature_table

        t = read_feature_table(path)
        action = t.action_names[0]
        return ObjectPopulation.fit({action: t.observations([action])[action]})
    # A Gaussian population whose between-object spread falls off over its 12 directions
    # (most objects differ in a few), noise correlated within each modality, noise levels
    # log-normal (sd 0.4), its spread scaled to the BioTac set's one-shot accuracy.
    rng = np.random.default_rng(7)
    d = 12
    basis = np.linalg.qr(rng.normal(size=(d, d)))[0]
    between = basis @ np.diag(np.exp(-np.arange(d) / 3.0)) @ basis.T
    within = np.eye(d)
    for cols in (slice(0, 8), slice(8, 12)):
        within[cols, cols] = 0.6 + 0.4 * np.eye(within[cols, cols].shape[0])
    pop = ActionPopulation(
        modalities={"a": 8, "b": 4},
        offset=np.zeros(d),
        unit=np.ones(d),
        centre=np.zeros(d),
        between=np.linalg.cholesky(between),
        within=np.linalg.cholesky(within),
        log_level_mean=0.0,
        log_level_sd=0.4,
    )
    scale = _matching_spread(pop, 0.85, 20, 25)
    from dataclasses import replace

    return ObjectPopulation({"A": replace(pop, between=scale * pop.between, spread_scale=scale)})


def measure(task: tuple[int, str, str | None, int | None]) -> dict:
    """One size and library model, in this (fresh) process."""
    n_objects, model, path, dask_workers = task
    os.environ.setdefault("RAYON_NUM_THREADS", "2")
    from aptkt.learning import APTKT, GPSettings, LearnerConfig, PoolEnvironment, PriorKnowledge
    from aptkt.learning.library import merge_priors

    pop = population(path)
    action = next(iter(pop.actions))
    library = {
        a: o.take(np.flatnonzero(o.trials < 12))
        for a, o in pop.draw(n_objects, 12, seed=STREAMS["library"], prefix="old").items()
    }
    new = pop.draw(5, 25, seed=STREAMS["new"], prefix="new")
    pool = {a: o.take(np.flatnonzero(o.trials < 12)) for a, o in new.items()}
    test = {a: o.take(np.flatnonzero(o.trials >= 12)) for a, o in new.items()}
    # New touches of the library's objects (their trials 12 and 13), 500 of them spread over it.
    touches = {}
    for a, o in pop.draw(n_objects, 14, seed=STREAMS["library"], prefix="old").items():
        later = np.flatnonzero(o.trials >= 12)
        touches[a] = o.take(later[np.linspace(0, later.size - 1, min(500, later.size)).astype(int)])
    gp = GPSettings(library_model=model)
    row: dict = {"objects": n_objects, "model": model}
    t, t_wall = _cpu(), time.perf_counter()
    try:
        prior = PriorKnowledge.build(library, gp=gp, seed=0)
    except MemoryError as exc:  # the exact model refuses what would not fit
        row["refused"] = str(exc)
        row["peak MB"] = round(_peak_mb())
        return row
    executor = None
    if dask_workers:
        from dask.distributed import Client, LocalCluster

        cluster = LocalCluster(
            n_workers=dask_workers, threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)
        from aptkt.experiments.executors import DaskExecutor

        executor = DaskExecutor(client)
    prior.precompute(None if executor is None else executor.imap_unordered)
    row["build CPU-s"] = round(_cpu() - t, 2)
    row["build wall-s"] = round(time.perf_counter() - t_wall, 2)
    if executor is not None:
        peaks = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
        cpus = client.run(_cpu)
        row["worker peak MB"] = round(max(peaks.values()))
        row["worker CPU-s"] = round(sum(cpus.values()), 1)
        client.close()
        cluster.close()
        return row | {"peak MB": round(_peak_mb())}
    names = sorted(set(new[action].objects.tolist()))
    t = _cpu()
    run = APTKT(LearnerConfig(budget=20, seed=0, gp=gp), prior).run(
        PoolEnvironment(pool, seed=0), [action], names, test=test
    )
    row["learn CPU-s"] = round(_cpu() - t, 2)
    updates = [s.seconds for s in run.steps[1:]]
    row["update max ms"] = round(1e3 * max(updates), 1)
    row["update median ms"] = round(1e3 * float(np.median(updates)), 1)
    row["one-shot accuracy"] = round(run.steps[0].mean_accuracy, 3)
    n_touches = sum(len(o) for o in touches.values())
    t = _cpu()
    prior.recognise(touches)
    row["recognise ms/touch"] = round(1e3 * (_cpu() - t) / n_touches, 3)
    learned = PriorKnowledge.build(pool, gp=prior.gp_settings, seed=0)
    t = _cpu()
    merged = merge_priors([("library", prior), ("learned", learned)])
    merged.precompute()
    row["merge CPU-s"] = round(_cpu() - t, 2)
    row["peak MB"] = round(_peak_mb())
    return row


def _child(task, conn) -> None:
    conn.send(measure(task))
    conn.close()


def in_process(task) -> dict:
    """``measure`` in a fresh spawned process (its own peak memory; not a pool's daemon, so
    that it may start a Dask cluster's workers)."""
    ctx = multiprocessing.get_context("spawn")
    receive, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(task, send))
    child.start()
    send.close()
    try:
        return receive.recv()
    finally:
        child.join()


def plot(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 8), constrained_layout=True)
    panels = [
        ("build CPU-s", "build (CPU s)"),
        ("learn CPU-s", "learn 5 new objects, budget 20 (CPU s)"),
        ("recognise ms/touch", "recognise (CPU ms per touch)"),
        ("peak MB", "peak memory (MB)"),
    ]
    for ax, (key, title) in zip(axes.flat, panels):
        for model, style in (("local", "o-"), ("exact", "s--")):
            pts = [(r["objects"], r[key]) for r in rows if r["model"] == model and key in r]
            if pts:
                x, y = zip(*pts)
                ax.plot(x, y, style, label=model)
        if key == "build CPU-s":
            x = np.array(sorted({r["objects"] for r in rows}))
            ref = [r for r in rows if r["model"] == "local" and key in r]
            if ref:
                k = ref[-1][key] / (x[-1] * np.log(x[-1]))
                ax.plot(x, k * x * np.log(x), ":", color="grey", label="∝ n log n")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("objects in the library")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--sizes", default="15,30,100,300,1000,3000,10000")
    parser.add_argument("--exact-up-to", type=int, default=100)
    parser.add_argument("--from", dest="table", help="fit the population on this feature table")
    parser.add_argument("--dask-at", type=int, help="also build this size on a local Dask cluster")
    parser.add_argument("--plot", default=str(RESULTS / "library-scale.png"))
    args = parser.parse_args()
    sizes = [int(k) for k in args.sizes.split(",")]
    rows = []
    for n in sizes:
        for model in ("local", "exact"):
            if model == "exact" and n > args.exact_up_to:
                continue
            row = in_process((n, model, args.table, None))
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.dask_at:
        row = in_process((args.dask_at, "local", args.table, 2))
        row["model"] = "local, Dask (2 workers)"
        rows.append(row)
        print(json.dumps(row), flush=True)
    columns = [
        "objects",
        "model",
        "build CPU-s",
        "learn CPU-s",
        "update max ms",
        "update median ms",
        "recognise ms/touch",
        "merge CPU-s",
        "peak MB",
        "one-shot accuracy",
        "worker peak MB",
        "worker CPU-s",
        "build wall-s",
    ]
    print(table(rows, columns))
    plot(rows, args.plot)
    print(
        save(
            "library-scale", {"table": args.table or "synthetic", "command": sys.argv, "rows": rows}
        )
    )


if __name__ == "__main__":
    main()
