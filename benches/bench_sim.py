"""Simulated world: CPU per trial as a ratio to a reference workload, data set generation at 1
and 2 processes, the main process's share of the CPU, and where the time goes.

    .venv/bin/python benches/bench_sim.py                      # writes benches/results/sim.json
    .venv/bin/python benches/bench_sim.py --trial-only         # writes benches/results/sim-trial.json
    .venv/bin/python benches/bench_sim.py --peer /path/to/other/checkout/python

* **CPU per trial**: every paper action on ``--objects`` objects, ``--reps`` trials each, in this
  process (``time.process_time`` around each ``SimWorld.explore``; warm caches), in ``--rounds``
  rounds, each trial followed by the fixed reference workload of ``_common.reference_workload``;
  the start-up (a fresh interpreter up to the world) once a round. Reported as ratios to the
  reference, median and range over the rounds: CPU-ms alone differ 1.3-1.7x between machines and
  move with the load of a shared one, and a ratio is what compares across them. CPU time, not
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
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import REFERENCE_VERSION, reference_workload, save, spread

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


#: What ``aptkt dataset generate`` does before its first trial: the interpreter, the command
#: line and generation modules, the world.
_STARTUP = (
    "import aptkt.cli, aptkt.runtime.generation\n"
    "from aptkt.sim.world import SimWorld\n"
    "SimWorld(seed=0)"
)


def _startup_ms() -> float:
    c = _cpu_children()
    subprocess.run([sys.executable, "-c", _STARTUP], check=True, cwd=HERE)
    return (_cpu_children() - c) * 1e3


def per_trial(n_objects: int, reps: int, rounds: int) -> dict:
    """CPU per simulated trial, as a ratio to the reference workload run beside it.

    Trials are simulated in this process under one BLAS thread, as ``dataset generate -j 1``
    simulates them (packing and writing, ≈ 1 ms a trial, are left out). A first pass over the plan fills the world's caches; then every round simulates the
    plan's trials afresh (the next ``reps`` trial numbers, as a longer plan would: a trial's drift
    is computed from the run's start, so far-off numbers cost more), each followed by one run of the
    reference, so that both see the same machine state, and ends with a start-up in a fresh
    interpreter (its CPU from ``getrusage``). A round's ratio is its trials' CPU over its
    references'."""
    from threadpoolctl import threadpool_limits

    from aptkt.sim.world import SimWorld

    plan = _plan(n_objects, reps)
    world = SimWorld(seed=plan.seed)
    trials = list(plan.trials())
    by_action: dict[str, list[float]] = {}
    out: list[dict[str, float]] = []
    with threadpool_limits(1, user_api="blas"):
        t = time.process_time()
        for obj, act, trial in trials:
            world.explore(obj, act, trial)
        first_pass = (time.process_time() - t) * 1e3 / len(trials)
        reference_workload()  # its first run loads what it needs of numpy
        for r in range(1, rounds + 1):
            trial_s = reference_s = 0.0
            for obj, act, trial in trials:
                t0 = time.process_time()
                world.explore(obj, act, trial + reps * r)
                t1 = time.process_time()
                reference_workload()
                t2 = time.process_time()
                trial_s += t1 - t0
                reference_s += t2 - t1
                by_action.setdefault(act.name, []).append((t1 - t0) * 1e3)
            startup = _startup_ms()
            trial_ms = trial_s * 1e3 / len(trials)
            reference_ms = reference_s * 1e3 / len(trials)
            out.append(
                {
                    "trial_ms": trial_ms,
                    "reference_ms": reference_ms,
                    "ratio": trial_ms / reference_ms,
                    "startup_ms": startup,
                    "startup_ratio": startup / reference_ms,
                }
            )
    return {
        "trials_per_round": len(trials),
        "rounds": out,
        "reference_version": REFERENCE_VERSION,
        **{k: spread([o[k] for o in out]) for k in out[0]},
        "first_pass_ms": first_pass,
        "by_action_ratio": {
            k: statistics.median(v) / spread([o["reference_ms"] for o in out])["median"]
            for k, v in by_action.items()
        },
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


def peer_per_trial(pythonpath: str, n_objects: int, reps: int, rounds: int) -> dict:
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
            "--rounds",
            str(rounds),
        ],
        env=env,
        check=True,
        capture_output=True,
        text=True,
        cwd=HERE,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _report(pt: dict, label: str = "") -> None:
    def r(k: str, unit: str = "", f: str = ".2f") -> str:
        v = pt[k]
        return f"{v['median']:{f}}{unit} ({v['min']:{f}}-{v['max']:{f}})"

    print(
        f"{label}trial / reference, median (range) over {len(pt['rounds'])} rounds of "
        f"{pt['trials_per_round']} trials: {r('ratio')}; start-up / reference {r('startup_ratio')}"
    )
    print(
        f"{label}  CPU-ms here: trial {r('trial_ms', ' ms', '.1f')}, reference "
        f"{r('reference_ms', ' ms', '.1f')}, start-up {r('startup_ms', ' ms', '.0f')}; first "
        f"pass (cold caches) {pt['first_pass_ms']:.1f} ms a trial"
    )
    print(
        f"{label}  by action (ratio): "
        + ", ".join(f"{k} {v:.2f}" for k, v in pt["by_action_ratio"].items())
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=3, help="objects of the paper's library")
    ap.add_argument("--reps", type=int, default=2, help="trials per object and action")
    ap.add_argument("--rounds", type=int, default=5, help="rounds of the CPU-per-trial ratio")
    ap.add_argument(
        "--gen-reps",
        type=int,
        default=4,
        help="trials per object and action in the generation runs",
    )
    ap.add_argument("--jobs", default="1,2", help="process counts for generation")
    ap.add_argument("--top", type=int, default=12, help="profile entries to show")
    ap.add_argument("--peer", help="PYTHONPATH of a checkout to compare CPU per trial with")
    ap.add_argument(
        "--trial-only", action="store_true", help="only the CPU per trial (results/sim-trial.json)"
    )
    ap.add_argument("--per-trial-only", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.per_trial_only:
        print(json.dumps(per_trial(args.objects, args.reps, args.rounds)))
        return

    load = os.getloadavg()
    result: dict = {
        "load_before": load,
        "objects": args.objects,
        "reps": args.reps,
        "command": " ".join(["bench_sim.py", *sys.argv[1:]]),
    }
    print(f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on {os.cpu_count()} cores")
    pt = result["per_trial"] = per_trial(args.objects, args.reps, args.rounds)
    _report(pt)
    if args.peer:
        peer = peer_per_trial(args.peer, args.objects, args.reps, args.rounds)
        result["peer_per_trial"], result["peer"] = peer, args.peer
        _report(peer, label="peer: ")
        print(
            f"peer / this, ratio to ratio: {peer['ratio']['median'] / pt['ratio']['median']:.2f}x"
        )
    if args.trial_only:
        result["load_after"] = os.getloadavg()
        print(f"wrote {save('sim-trial', result)}")
        return
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
