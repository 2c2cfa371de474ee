"""Simulated world: CPU per trial, data set generation at 1 and 2 processes, the main process's
share of the CPU, and where the time goes.

    .venv/bin/python benches/bench_sim.py                      # writes benches/results/sim.json
    .venv/bin/python benches/bench_sim.py --peer /path/to/other/checkout/python

* **CPU per trial**: every paper action on ``--objects`` objects, ``--reps`` trials each, in this
  process (``time.process_time`` around each ``SimWorld.explore``; warm caches). CPU time, not
  wall time: the machine is shared, and CPU time is what a core delivers.
* **Generation**: ``aptkt.runtime.generation.generate`` of the same plan at 1 and 2 processes:
  trials per wall second, CPU of the main process (receiving, writing, flushing) and of the
  workers (``getrusage`` of the reaped children, interpreter start included), the main
  process's share of the total.
* **Profile**: the top entries (own CPU time) of a cProfile run over the same trials.
* ``--peer``: the CPU-per-trial measurement repeated side by side with another checkout's
  ``python/`` directory (e.g. the commit before a change), same trials, same process setup.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import save

HERE = Path(__file__).resolve().parent


def _cpu_self() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _plan(n_objects: int, reps: int, seed: int = 0):
    from aptkt.actions import PAPER_ACTIONS
    from aptkt.runtime.generation import GenerationPlan
    from aptkt.sim.objects import default_library

    objects = tuple(default_library())[:n_objects]
    return GenerationPlan(objects, tuple(PAPER_ACTIONS.values()), reps, seed)


def per_trial(n_objects: int, reps: int) -> dict:
    """CPU ms of every trial of the plan, simulated in this process after a warm-up trial."""
    from aptkt.sim.world import SimWorld

    plan = _plan(n_objects, reps)
    world = SimWorld(seed=plan.seed)
    world.explore(plan.objects[0], plan.actions[0], 10_000)  # caches (thermal systems, imports)
    by_action: dict[str, list[float]] = {}
    for obj, act, trial in plan.trials():
        t = time.process_time()
        world.explore(obj, act, trial)
        by_action.setdefault(act.name, []).append((time.process_time() - t) * 1e3)
    every = [x for v in by_action.values() for x in v]
    return {
        "trials": len(every),
        "mean_ms": sum(every) / len(every),
        "median_ms": sorted(every)[len(every) // 2],
        "by_action_ms": {k: sum(v) / len(v) for k, v in by_action.items()},
    }


def generation(n_objects: int, reps: int, jobs: int) -> dict:
    from aptkt.runtime.generation import generate

    plan = _plan(n_objects, reps)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"bench_{jobs}.h5"
        c_self, c_child, wall = _cpu_self(), _cpu_children(), time.perf_counter()
        info = generate(path, plan, jobs=jobs, progress=False)
        wall = time.perf_counter() - wall
        main = _cpu_self() - c_self
        workers = _cpu_children() - c_child
        size = path.stat().st_size
    n = len(plan)
    total = main + workers
    return {
        "jobs": jobs,
        "trials": n,
        "wall_s": wall,
        "trials_per_s": n / wall,
        "cpu_main_s": main,
        "cpu_workers_s": workers,
        "cpu_ms_per_trial": total / n * 1e3,
        "main_share": main / total,
        "file_mb": size / 1e6,
        "samples": info["samples"],
    }


def profile(n_objects: int, reps: int, top: int) -> list[dict]:
    from aptkt.sim.world import SimWorld

    plan = _plan(n_objects, reps)
    world = SimWorld(seed=plan.seed)
    world.explore(plan.objects[0], plan.actions[0], 10_000)
    prof = cProfile.Profile(time.process_time)
    prof.enable()
    for obj, act, trial in plan.trials():
        world.explore(obj, act, trial)
    prof.disable()
    stats = pstats.Stats(prof, stream=io.StringIO())
    total = sum(v[2] for v in stats.stats.values())
    rows = []
    for (file, line, fn), (_, calls, tottime, cumtime, _) in sorted(
        stats.stats.items(), key=lambda kv: -kv[1][2]
    )[:top]:
        where = f"{Path(file).name}:{line}({fn})" if file != "~" else fn
        rows.append(
            {
                "function": where,
                "calls": calls,
                "own_ms_per_trial": tottime / len(plan) * 1e3,
                "own_share": tottime / total,
                "cum_ms_per_trial": cumtime / len(plan) * 1e3,
            }
        )
    return rows


def peer_per_trial(pythonpath: str, n_objects: int, reps: int) -> dict:
    env = dict(os.environ, PYTHONPATH=pythonpath)
    out = subprocess.run(
        [
            sys.executable,
            str(Path(__file__)),
            "--per-trial-only",
            "--objects",
            str(n_objects),
            "--reps",
            str(reps),
        ],
        env=env,
        check=True,
        capture_output=True,
        text=True,
        cwd=HERE,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=3, help="objects of the paper's library")
    ap.add_argument("--reps", type=int, default=2, help="trials per object and action")
    ap.add_argument(
        "--gen-reps",
        type=int,
        default=4,
        help="trials per object and action in the generation runs",
    )
    ap.add_argument("--jobs", default="1,2", help="process counts for generation")
    ap.add_argument("--top", type=int, default=12, help="profile entries to show")
    ap.add_argument("--peer", help="PYTHONPATH of a checkout to compare CPU per trial with")
    ap.add_argument("--per-trial-only", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.per_trial_only:
        print(json.dumps(per_trial(args.objects, args.reps)))
        return

    load = os.getloadavg()
    result: dict = {"load_before": load, "objects": args.objects, "reps": args.reps}
    result["per_trial"] = per_trial(args.objects, args.reps)
    pt = result["per_trial"]
    print(f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on {os.cpu_count()} cores")
    print(
        f"CPU per trial ({pt['trials']} trials): mean {pt['mean_ms']:.1f} ms, "
        f"median {pt['median_ms']:.1f} ms"
    )
    print("  by action: " + ", ".join(f"{k} {v:.1f}" for k, v in pt["by_action_ms"].items()))
    if args.peer:
        peer = result["peer_per_trial"] = peer_per_trial(args.peer, args.objects, args.reps)
        result["peer"] = args.peer
        print(
            f"peer {args.peer}: mean {peer['mean_ms']:.1f} ms, median "
            f"{peer['median_ms']:.1f} ms -> {peer['mean_ms'] / pt['mean_ms']:.2f}x"
        )
    gens = []
    for jobs in [int(j) for j in args.jobs.split(",")]:
        g = generation(args.objects, args.gen_reps, jobs)
        gens.append(g)
        print(
            f"generate, {jobs} process(es), {g['trials']} trials: {g['trials_per_s']:.2f} "
            f"trials/s, {g['cpu_ms_per_trial']:.1f} CPU-ms/trial, main process "
            f"{g['cpu_main_s']:.2f} s CPU = {100 * g['main_share']:.1f} % of "
            f"{g['cpu_main_s'] + g['cpu_workers_s']:.2f} s"
        )
    result["generation"] = gens
    if len(gens) >= 2:
        result["speedup"] = gens[1]["trials_per_s"] / gens[0]["trials_per_s"]
        print(
            f"speed-up {gens[1]['jobs']} vs {gens[0]['jobs']} processes: "
            f"{result['speedup']:.2f}x (wall clock)"
        )
    result["profile"] = profile(args.objects, 1, args.top)
    print("profile (own CPU per trial):")
    for r in result["profile"]:
        print(
            f"  {r['own_ms_per_trial']:6.2f} ms {100 * r['own_share']:5.1f} %  "
            f"{r['calls']:6d} calls  {r['function']}"
        )
    result["load_after"] = os.getloadavg()
    print(f"wrote {save('sim', result)}")


if __name__ == "__main__":
    main()
