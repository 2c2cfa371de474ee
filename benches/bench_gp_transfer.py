"""Transfer variants of the dependent kernel on the demo's world, one observation per object.

Usage: python benches/bench_gp_transfer.py [--data FILE] [--runs R] [--actions P1,S1,...]
(also reached as ``python benches/bench_gp.py --transfer-variants``)

The demo's objects (3 priors, 5 new objects) are simulated into FILE if it does not exist
(seed 0, 20 trials per object and action, as ``aptkt demo``). For each action and each run r,
every new object contributes its training trial r as its single observation (the target); the
new objects' trials 10-19 are the test set. All variants work in the prior's feature space
(the pipeline fitted on the priors' trials 0-9), fit ``LaplaceGPC`` with the learner's GP
settings (``length_scale="auto"``, 1 restart, 100 iterations) and differ only in what the new
object's one-vs-all classifier receives:

  none            no source;
  positives ML-II the most related old object's observations, all +1 (the paper's reading);
  one-vs-all ML-II that old object's one-vs-all task: its observations +1, the other old
                  objects' -1;
  one-vs-all MAP  the same with hyper_prior="weak";
  multi MAP       every old object whose relatedness reaches 0.4, each with its own λ, all as
                  one-vs-all tasks, hyper_prior="weak".

Relatedness (paper §4.2): p̄_i = the prior's binary classifier i's own p(y = +1 | v) at the new
object's observation (``predict_proba_binary``); the single-source variants always transfer
from argmax p̄ with λ = p̄ (no cut-off, so the kernels are compared on every decision).
Reports accuracy on the test set averaged over actions and runs, and for the transfer
classifiers the median fitted length-scale relative to the data scale and the median σ².
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from _common import save, table

from aptkt.gp import LaplaceGPC, TransferSource
from aptkt.learning import GPSettings, PriorKnowledge
from aptkt.learning.dataset import load_observations

PRIORS = ("rough_sponge", "paper_box", "metal_toolbox")
NEW = ("smooth_sponge", "hard_box", "biscuit_box", "mouse_pad", "bamboo_board")
ACTIONS = ("P1", "P2", "S1", "S2", "S3", "S4", "C1")
VARIANTS = ("none", "positives ML-II", "one-vs-all ML-II", "one-vs-all MAP", "multi MAP")
EPS_NEG = 0.4


def ensure_data(path: Path, jobs: int) -> None:
    if path.exists():
        return
    from aptkt.actions import PAPER_ACTIONS
    from aptkt.runtime.generation import GenerationPlan, generate

    plan = GenerationPlan(PRIORS + NEW, tuple(PAPER_ACTIONS[a] for a in ACTIONS), 20, 0)
    generate(path, plan, jobs=jobs, resume=False, progress=True)


def median_pairwise(X: np.ndarray) -> float:
    d = np.sqrt(((X[:, None, :] - X[None, :, :]) ** 2).sum(-1))
    v = d[np.triu_indices(len(X), 1)]
    v = v[v > 0]
    return float(np.median(v)) if v.size else 1.0


def run_action(prior, table_new, runs: int, seed: int) -> dict:
    action = prior.action
    old_X = prior.training_features()
    old_y = prior.observations.objects
    obs = table_new
    X_all, groups = prior.pipeline.transform(obs)
    test = obs.trials >= 10
    Xt, yt = X_all[test], obs.objects[test]
    gp = GPSettings()
    acc = {v: [] for v in VARIANTS}
    collapse = {v: [] for v in VARIANTS}
    for r in range(runs):
        train = obs.trials == r
        X, y = X_all[train], obs.objects[train]
        pbar = prior.model.predict_proba_binary(X)  # (n_new, n_old)
        olds = list(prior.model.classes_)
        single: dict = {}
        multi: dict = {}
        for k, obj in enumerate(y):
            best = int(np.argmax(pbar[k]))
            single[obj] = (olds[best], float(pbar[k, best]))
            multi[obj] = [
                (olds[i], float(pbar[k, i])) for i in range(len(olds)) if pbar[k, i] >= EPS_NEG
            ]
        for variant in VARIANTS:
            sources = {}
            for obj in y:
                old, lam = single[obj]
                if variant == "positives ML-II":
                    sources[obj] = TransferSource(
                        old_X[old_y == old], transfer_lambda=lam, name=old
                    )
                elif variant in ("one-vs-all ML-II", "one-vs-all MAP"):
                    sources[obj] = TransferSource(old_X, old_y == old, lam, name=old)
                elif variant == "multi MAP" and multi[obj]:
                    sources[obj] = [
                        TransferSource(old_X, old_y == o, lam, name=o) for o, lam in multi[obj]
                    ]
            model = LaplaceGPC(
                length_scale=gp.length_scale,
                modalities=groups,
                n_restarts=gp.n_restarts,
                max_iter=gp.max_iter,
                random_state=seed + r,
                hyper_prior="weak" if "MAP" in variant else None,
            ).fit(X, y, sources=sources or None)
            acc[variant].append(float(np.mean(model.predict(Xt) == yt)))
            scale = {m: median_pairwise(X[:, cols]) for m, cols in groups.items()}
            for hp in model.hyperparameters_.values():
                if hp["transfer_lambda"]:
                    rel = [hp["length_scales"][m] / scale[m] for m in scale]
                    collapse[variant].append((float(np.median(rel)), hp["signal_variance"]))
    return {"action": action, "acc": acc, "collapse": collapse}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", type=Path, default=Path("aptkt-bench-transfer.h5"))
    parser.add_argument("--runs", type=int, default=10, help="training trials used in turn (<= 10)")
    parser.add_argument("--actions", default=",".join(ACTIONS))
    parser.add_argument(
        "--jobs", type=int, default=1, help="simulation processes if data is missing"
    )
    args = parser.parse_args()
    actions = tuple(args.actions.split(","))
    ensure_data(args.data, args.jobs)
    t0 = time.perf_counter()
    prior_table = load_observations(args.data, actions=actions, objects=PRIORS, trials=range(10))
    new_table = load_observations(args.data, actions=actions, objects=NEW)
    prior = PriorKnowledge.build(prior_table, gp=GPSettings(), seed=0)
    results = [run_action(prior[a], new_table[a], args.runs, seed=0) for a in actions]
    rows = []
    for v in VARIANTS:
        accs = [np.mean(res["acc"][v]) for res in results]
        pairs = [p for res in results for p in res["collapse"][v]]
        row = {"variant": v, "accuracy": float(np.mean(accs))}
        row.update({f"acc {res['action']}": float(np.mean(res["acc"][v])) for res in results})
        if pairs:
            row["median ℓ / data scale"] = statistics.median(p[0] for p in pairs)
            row["median σ²"] = statistics.median(p[1] for p in pairs)
        rows.append(row)
        print(row, flush=True)
    cols = ["variant", "accuracy", "median ℓ / data scale", "median σ²"] + [
        f"acc {a}" for a in actions
    ]
    print(table(rows, cols))
    print(
        "saved",
        save(
            "gp-transfer",
            {
                "rows": rows,
                "runs": args.runs,
                "actions": actions,
                "seconds": time.perf_counter() - t0,
            },
        ),
    )


if __name__ == "__main__":
    main()
