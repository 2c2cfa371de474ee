"""The full Fig. 7 experiment: our Rust core vs the same loop on scikit-learn's GPC.

Usage: python benches/bench_experiments.py --data sim40.h5 [--sk-groups 2] [--sk-trials 1]

Fig. 7 (paper §5.4) is 10 groups of 3 prior objects × 5 trials × {APTKT, baseline}: 10 prior-
knowledge builds and 100 learning runs (7 actions, 5 new objects, budget 40), i.e. 4,000 model
updates and their predictions. Both sides run the *same loop* (``aptkt.learning.APTKT`` on the
same pools, seeds and test sets, in this one process, one thread each); only the observation
model differs:

* ours: ``aptkt.gp.LaplaceGPC`` — multi-modal kernel (one RBF per modality, weights γ, signal
  variance; 1 + 1 starts), the dependent transfer kernel with λ from Eq. 3;
* scikit-learn: one binary ``GaussianProcessClassifier`` per new object (one-vs-all; a single
  one for two classes, as ours), kernel ``ConstantKernel * RBF`` — one isotropic length-scale
  on the concatenated modalities (no per-modality length-scales or weights: scikit-learn
  kernels cannot act on column subsets), 1 restart. Transfer cannot be expressed either: the
  prior object's observations are added to that object's classifier as positives with the
  full kernel between them — λ = 1 instead of λ = p̄. The training sets therefore have the
  same sizes as ours, which is what the time depends on.

The scikit-learn side is slow, so it runs a subset (``--sk-groups`` groups × ``--sk-trials``
trials, both methods, with those groups' prior builds); our core runs the same subset and the
full experiment. The full scikit-learn time is extrapolated from the subset as
``measured × (full-size time of ours / subset time of ours)`` — i.e. assuming scikit-learn's
cost scales across groups and trials as ours does — and, as a check, by counting
(mean time per prior build × 10 + mean time per run × 100).
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from dataclasses import dataclass

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one thread each: BLAS for scikit-learn
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from _common import save, table  # noqa: E402

from aptkt.experiments.figures.base import Context  # noqa: E402
from aptkt.experiments.figures.common import prior_groups  # noqa: E402
from aptkt.experiments.reproduce import _paper_numbers  # noqa: E402
from aptkt.experiments.run_store import data_fingerprint  # noqa: E402
from aptkt.experiments.scale import Scale  # noqa: E402
from aptkt.learning import APTKT, GPSettings, PoolEnvironment, PriorKnowledge  # noqa: E402
from aptkt.learning.dataset import load_observations  # noqa: E402


class SklearnOneVsAll:
    """The observation-model interface the learner uses (fit with sources, predict_proba,
    classes_), on scikit-learn's binary Laplace GPC."""

    def __init__(self, random_state: int, n_restarts: int) -> None:
        self.random_state = random_state
        self.n_restarts = n_restarts

    def _gpc(self, X: np.ndarray):
        from sklearn.gaussian_process import GaussianProcessClassifier
        from sklearn.gaussian_process.kernels import RBF, ConstantKernel

        d = np.sqrt(((X[:, None, :] - X[None, :, :]) ** 2).sum(-1))
        scale = (
            float(np.median(d[d > 0])) if np.any(d > 0) else 1.0
        )  # start scaled to the data, as ours
        kernel = ConstantKernel(1.0, (1e-3, 1e3)) * RBF(scale, (1e-3, 1e3))
        return GaussianProcessClassifier(
            kernel, n_restarts_optimizer=self.n_restarts, random_state=self.random_state
        )

    def fit(self, X, y, sources=None):
        from sklearn.exceptions import ConvergenceWarning

        X, y = np.asarray(X), np.asarray(y)
        self.classes_ = np.unique(y)
        sources = sources or {}
        self.models_ = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            if len(self.classes_) == 2 and not sources:
                self.models_ = [self._gpc(X).fit(X, y == self.classes_[1])]
                return self
            for c in self.classes_:
                Xc, yc = X, (y == c)
                if c in sources:
                    Xs = np.asarray(sources[c].X)
                    Xc, yc = np.vstack([Xs, X]), np.concatenate([np.ones(len(Xs), bool), yc])
                self.models_.append(self._gpc(Xc).fit(Xc, yc))
        return self

    def predict_proba(self, X):
        X = np.asarray(X)
        if len(self.models_) == 1:
            p = self.models_[0].predict_proba(X)[:, 1]
            return np.column_stack([1 - p, p])
        P = np.column_stack([m.predict_proba(X)[:, 1] for m in self.models_])
        return P / P.sum(axis=1, keepdims=True)


@dataclass(frozen=True)
class SklearnGPSettings(GPSettings):
    """GP settings whose models are scikit-learn's (same restarts as ours)."""

    def make(self, modalities, random_state):  # noqa: ARG002 - scikit-learn has one kernel on all columns
        return SklearnOneVsAll(random_state % 2**31, self.n_restarts)


def experiment(ctx: Context, gp: GPSettings, groups: list[int], trials: list[int]) -> dict:
    """Fig. 7's loop for the given groups and trials: prior builds and runs, timed. The groups
    and trial seeds are the ones ``aptkt reproduce fig7`` uses (``prior_group_plan``)."""
    s = ctx.scale
    all_groups = prior_groups(ctx, s.n_priors)
    pool = load_observations(
        ctx.data, actions=s.actions, objects=s.new_objects, trials=s.pool_trials
    )
    test = load_observations(
        ctx.data, actions=s.actions, objects=s.new_objects, trials=s.test_trials
    )
    prior_s, run_s, final = [], {"baseline": [], "APTKT": []}, {"baseline": [], "APTKT": []}
    t_all = time.perf_counter()
    for g in groups:
        table_ = load_observations(
            ctx.data, actions=s.actions, objects=all_groups[g], trials=s.pool_trials
        )
        t0 = time.perf_counter()
        prior = PriorKnowledge.build(table_, gp=gp, seed=ctx.seed)
        prior_s.append(time.perf_counter() - t0)
        for t in trials:
            seed = ctx.seed_for("trial", s.n_priors, g, t)
            for m in ("baseline", "APTKT"):
                cfg = ctx.learner(m, seed=seed, gp=gp)
                t0 = time.perf_counter()
                run = APTKT(cfg, prior).run(
                    PoolEnvironment(pool, seed=seed), s.actions, s.new_objects, test
                )
                run_s[m].append(time.perf_counter() - t0)
                final[m].append(run.steps[-1].mean_accuracy)
    return {
        "groups": len(groups),
        "trials": len(trials),
        "runs": sum(len(v) for v in run_s.values()),
        "seconds": time.perf_counter() - t_all,
        "prior_build_mean_s": float(np.mean(prior_s)),
        "run_mean_s": {m: float(np.mean(v)) for m, v in run_s.items()},
        "final_accuracy": {m: float(np.mean(v)) for m, v in final.items()},
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--data",
        required=True,
        help="the full data set (e.g. sim40.h5 from `aptkt dataset generate`)",
    )
    parser.add_argument(
        "--sk-groups", type=int, default=2, help="groups run on scikit-learn (default %(default)s)"
    )
    parser.add_argument(
        "--sk-trials",
        type=int,
        default=1,
        help="trials per group on scikit-learn (default %(default)s)",
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    scale = Scale.full()
    ctx = Context(
        scale=scale,
        seed=args.seed,
        data=args.data,
        fingerprint=data_fingerprint(args.data),
        output=None,
        index=_paper_numbers(scale.objects),
    )  # type: ignore[arg-type]
    ours_gp = GPSettings(n_jobs=1)
    sk_gp = SklearnGPSettings(n_jobs=1)
    groups = list(range(min(args.sk_groups, scale.groups)))
    trials = list(range(min(args.sk_trials, scale.trials)))
    load = os.getloadavg()
    print(f"load average {load[0]:.1f}; ours, full experiment ...", flush=True)
    ours_full = experiment(ctx, ours_gp, list(range(scale.groups)), list(range(scale.trials)))
    print(f"  {ours_full['seconds']:.1f} s; ours, subset ...", flush=True)
    ours_sub = experiment(ctx, ours_gp, groups, trials)
    print(f"  {ours_sub['seconds']:.1f} s; scikit-learn, subset ...", flush=True)
    sk_sub = experiment(ctx, sk_gp, groups, trials)
    print(f"  {sk_sub['seconds']:.1f} s", flush=True)
    n_runs_full = scale.groups * scale.trials * 2
    sk_by_ratio = sk_sub["seconds"] * ours_full["seconds"] / ours_sub["seconds"]
    sk_by_count = (
        sk_sub["prior_build_mean_s"] * scale.groups
        + np.mean(list(sk_sub["run_mean_s"].values())) * n_runs_full
    )
    rows = [
        {
            "side": "aptkt core",
            "what": f"full: {scale.groups} groups × {scale.trials} trials × 2 methods",
            "seconds": ours_full["seconds"],
            "prior build s": ours_full["prior_build_mean_s"],
            "run s (baseline / APTKT)": f"{ours_full['run_mean_s']['baseline']:.2f} / {ours_full['run_mean_s']['APTKT']:.2f}",
            "final accuracy (baseline / APTKT)": f"{ours_full['final_accuracy']['baseline']:.3f} / {ours_full['final_accuracy']['APTKT']:.3f}",
        },
        {
            "side": "aptkt core",
            "what": f"subset: {len(groups)} groups × {len(trials)} trials × 2",
            "seconds": ours_sub["seconds"],
            "prior build s": ours_sub["prior_build_mean_s"],
            "run s (baseline / APTKT)": f"{ours_sub['run_mean_s']['baseline']:.2f} / {ours_sub['run_mean_s']['APTKT']:.2f}",
            "final accuracy (baseline / APTKT)": f"{ours_sub['final_accuracy']['baseline']:.3f} / {ours_sub['final_accuracy']['APTKT']:.3f}",
        },
        {
            "side": "scikit-learn",
            "what": f"subset: {len(groups)} groups × {len(trials)} trials × 2",
            "seconds": sk_sub["seconds"],
            "prior build s": sk_sub["prior_build_mean_s"],
            "run s (baseline / APTKT)": f"{sk_sub['run_mean_s']['baseline']:.2f} / {sk_sub['run_mean_s']['APTKT']:.2f}",
            "final accuracy (baseline / APTKT)": f"{sk_sub['final_accuracy']['baseline']:.3f} / {sk_sub['final_accuracy']['APTKT']:.3f}",
        },
        {
            "side": "scikit-learn",
            "what": "full, extrapolated (× ours' full/subset ratio)",
            "seconds": sk_by_ratio,
        },
        {
            "side": "scikit-learn",
            "what": "full, extrapolated (counting builds and runs)",
            "seconds": sk_by_count,
        },
    ]
    print(
        table(
            rows,
            [
                "side",
                "what",
                "seconds",
                "prior build s",
                "run s (baseline / APTKT)",
                "final accuracy (baseline / APTKT)",
            ],
        )
    )
    print(
        f"ratio on the same subset (scikit-learn / ours): {sk_sub['seconds'] / ours_sub['seconds']:.1f}×; "
        f"full experiment, extrapolated: {sk_by_ratio / ours_full['seconds']:.1f}× "
        f"(by counting: {sk_by_count / ours_full['seconds']:.1f}×)"
    )
    path = save(
        "experiments",
        {
            "load_average": load,
            "ours_full": ours_full,
            "ours_subset": ours_sub,
            "sklearn_subset": sk_sub,
            "sklearn_full_extrapolated_ratio_method": sk_by_ratio,
            "sklearn_full_extrapolated_count_method": sk_by_count,
            "ratio_subset": sk_sub["seconds"] / ours_sub["seconds"],
            "ratio_full_extrapolated": sk_by_ratio / ours_full["seconds"],
        },
    )
    print(f"saved {path}")


if __name__ == "__main__":
    main()
