"""LaplaceGPC vs scikit-learn's GaussianProcessClassifier, side by side on the same data.

Usage: python benches/bench_gp.py [--quick] [--skip-sklearn-opt-above N] [--single-thread]
       python benches/bench_gp.py --transfer-variants [bench_gp_transfer.py's options]
       python benches/bench_gp.py --large [--sizes 1000,2000] [--sklearn-max 1000] [--other DIR]

--large: a 3-class fit (6 features, random_state=0) at each size, each in a fresh process:
today's defaults on one thread (n_jobs=None) and on every core (n_jobs=-1), the former settings
(length_scale=1.0, n_restarts=2, max_iter=200), and scikit-learn's GaussianProcessClassifier
with as many starts (up to --sklearn-max rows: it is slow). Reports wall time, CPU time, the
busiest thread's CPU time (what the fit takes on an idle machine with that many cores), peak
resident memory (ru_maxrss, the data included) and the load average before and after. BLAS
runs on one thread. With --other DIR (the python/ directory of another checkout, e.g. an older
commit with its own compiled extension) the default settings also run on that implementation.

By default each side runs as a user gets it: ours fits the one-vs-all classifiers in parallel on
all cores, scikit-learn fits them one after the other with a multi-threaded BLAS. With
--single-thread both run on one thread (ours n_jobs=1, BLAS limited by threadpoolctl), which
compares the numerics alone.

For each n (and d), one data set with 5 classes; reports for
  fixed-kernel fit, optimised fit with the same number of starts (1 + 2 restarts),
  predict_proba on 1000 points,
the wall times, their ratio (sklearn / aptkt), the LML per class reached by both optimised fits
and the test accuracies.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np
from _common import best_of, median_of, save, table
from sklearn.datasets import make_classification
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessClassifier
from sklearn.gaussian_process.kernels import RBF, ConstantKernel
from threadpoolctl import threadpool_limits

from aptkt.gp import LaplaceGPC

RESTARTS = 2


def data(n: int, d: int, seed: int = 0):
    X, y = make_classification(
        n_samples=n + 500,
        n_features=d,
        n_informative=min(d, 6),
        n_redundant=0,
        n_classes=5,
        n_clusters_per_class=1,
        class_sep=1.5,
        random_state=seed,
    )
    X = (X - X.mean(0)) / X.std(0)
    return X[:n], y[:n], X[n:], y[n:]


def per_class_lml(model: GaussianProcessClassifier) -> np.ndarray:
    return np.array([e.log_marginal_likelihood_value_ for e in model.base_estimator_.estimators_])


def run(n: int, d: int, sklearn_opt: bool, n_jobs: int | None = None) -> dict:
    X, y, Xt, yt = data(n, d)
    Xp = np.random.default_rng(1).normal(size=(1000, d))
    row: dict = {"n": n, "d": d}

    fixed_kernel = ConstantKernel(2.0, "fixed") * RBF(np.sqrt(d), "fixed")

    def sk_fixed():
        return GaussianProcessClassifier(fixed_kernel, optimizer=None).fit(X, y)

    def ours_fixed():
        return LaplaceGPC(np.sqrt(d), 2.0, optimize=False, n_jobs=n_jobs).fit(X, y)

    row["fixed sklearn s"] = median_of(sk_fixed)
    row["fixed aptkt s"] = median_of(ours_fixed)
    row["fixed ratio"] = row["fixed sklearn s"] / row["fixed aptkt s"]

    sk_model = sk_fixed()
    our_model = ours_fixed()
    row["predict sklearn s"] = best_of(lambda: sk_model.predict_proba(Xp))
    row["predict aptkt s"] = best_of(lambda: our_model.predict_proba(Xp))
    row["predict ratio"] = row["predict sklearn s"] / row["predict aptkt s"]

    # Same starts as scikit-learn's (length-scale 1, then random restarts), its iteration cap.
    ours = LaplaceGPC(1.0, n_restarts=RESTARTS, max_iter=200, random_state=0, n_jobs=n_jobs)
    row["opt aptkt s"] = median_of(lambda: ours.fit(X, y), repeat=3 if n <= 400 else 1)
    row["aptkt LML (sum)"] = float(ours.log_marginal_likelihood_.sum())
    row["aptkt acc"] = ours.score(Xt, yt)
    if sklearn_opt:
        sk = GaussianProcessClassifier(
            ConstantKernel(1.0) * RBF(1.0), n_restarts_optimizer=RESTARTS, random_state=0
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            row["opt sklearn s"] = median_of(lambda: sk.fit(X, y), repeat=1)
        row["opt ratio"] = row["opt sklearn s"] / row["opt aptkt s"]
        sk_lml = per_class_lml(sk)
        row["sklearn LML (sum)"] = float(sk_lml.sum())
        row["classes with LML >= sklearn"] = int(
            np.sum(ours.log_marginal_likelihood_ >= sk_lml - 1e-6 * np.abs(sk_lml))
        )
        row["sklearn acc"] = sk.score(Xt, yt)
    return row


LARGE_CHILD = """
import os, resource, sys, threading, time
import numpy as np
from sklearn.datasets import make_classification
impl, n, length_scale, restarts, max_iter, n_jobs = sys.argv[1:7]
n, restarts, max_iter = int(n), int(restarts), int(max_iter)
X, y = make_classification(n_samples=n, n_features=6, n_informative=4, n_redundant=0,
                           n_classes=3, n_clusters_per_class=1, random_state=0)
if impl == "sklearn":
    from sklearn.gaussian_process import GaussianProcessClassifier
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel
    model = GaussianProcessClassifier(ConstantKernel(1.0) * RBF(float(length_scale)),
                                      n_restarts_optimizer=restarts, random_state=0)
else:
    from aptkt.gp import LaplaceGPC
    length_scale = length_scale if length_scale == "auto" else float(length_scale)
    model = LaplaceGPC(length_scale, n_restarts=restarts, max_iter=max_iter, random_state=0,
                       n_jobs=None if n_jobs == "none" else int(n_jobs))

# CPU seconds of every thread, sampled while the fit runs (the fit's threads end with it):
# the busiest thread's figure is what the fit would take on an idle machine with that many
# cores, whatever share of them the other jobs left us.
ticks = os.sysconf("SC_CLK_TCK")
def thread_cpu():
    out = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            fields = open(f"/proc/self/task/{tid}/stat").read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[tid] = (int(fields[11]) + int(fields[12])) / ticks
    return out
busy, done = {}, threading.Event()
def sample():
    while not done.wait(0.05):
        busy.update(thread_cpu())
before = thread_cpu()
sampler = threading.Thread(target=sample, daemon=True)
sampler.start()
load0 = os.getloadavg()[0]
t, c = time.perf_counter(), time.process_time()
model.fit(X, y)
wall, cpu = time.perf_counter() - t, time.process_time() - c
done.set(); sampler.join()
busy.update({tid: v for tid, v in thread_cpu().items() if tid in busy})
busiest = max(v - before.get(tid, 0.0) for tid, v in busy.items())
load1 = os.getloadavg()[0]
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
lml = (float(model.log_marginal_likelihood_.sum()) if impl != "sklearn" else
       float(sum(e.log_marginal_likelihood_value_ for e in model.base_estimator_.estimators_)))
print(wall, cpu, busiest, peak, model.score(X, y), lml, load0, load1)
"""

#: (label, implementation, length_scale, n_restarts, max_iter, n_jobs): today's defaults on one
#: thread (n_jobs=None, the default) and on every core, the former settings (length-scale 1.0,
#: 2 restarts, 200 iterations), and scikit-learn with the same number of starts as our default
#: (its optimiser from length-scale 1, then one random restart; its BLAS on one thread).
LARGE_SETTINGS = (
    ("default (auto, 1, 100), n_jobs=None", "this", "auto", 1, 100, "none"),
    ("default (auto, 1, 100), n_jobs=-1", "this", "auto", 1, 100, "-1"),
    ("former (1.0, 2, 200), n_jobs=None", "this", "1.0", 2, 200, "none"),
    ("scikit-learn (1.0, 1 restart)", "sklearn", "1.0", 1, 0, "none"),
)


def run_large(sizes: list[int], other: str | None, sklearn_max: int) -> None:
    """Each fit in a fresh process; with ``other`` (a python/ directory of another checkout)
    the default settings also run on that implementation, side by side; scikit-learn only up
    to ``sklearn_max`` rows (it is slow)."""
    import os
    import subprocess
    import sys

    rows = []
    here = str(Path(__file__).resolve().parents[1] / "python")
    for n in sizes:
        runs = [(path_for, *cfg) for cfg in LARGE_SETTINGS for path_for in [here]]
        runs = [r for r in runs if r[2] != "sklearn" or n <= sklearn_max]
        if other:
            runs.append(
                (other, "default (auto, 1, 100), n_jobs=None", "other", "auto", 1, 100, "none")
            )
        for path, label, impl, ls, restarts, max_iter, n_jobs in runs:
            env = {**os.environ, "PYTHONPATH": path, "OPENBLAS_NUM_THREADS": "1"}
            args = [impl, str(n), ls, str(restarts), str(max_iter), n_jobs]
            out = subprocess.run(
                [sys.executable, "-c", LARGE_CHILD, *args],
                capture_output=True,
                text=True,
                check=True,
                env=env,
            ).stdout.split()
            wall, cpu, busiest, peak, acc, lml, load0, load1 = map(float, out)
            row = {
                "n": n,
                "implementation": impl,
                "settings": label,
                "wall s": wall,
                "cpu s": cpu,
                "busiest thread cpu s": busiest,
                "peak MB": peak,
                "load": f"{load0:.1f}-{load1:.1f}",
                "train acc": acc,
                "LML (sum)": lml,
            }
            rows.append(row)
            print(row, flush=True)
    print(table(rows, list(rows[0])))
    print("saved", save("gp-large", {"rows": rows, "other": other}))


def main() -> None:
    import sys

    if "--large" in sys.argv:
        opt = {"--sizes": "1000,2000", "--other": None, "--sklearn-max": "1000"}
        for key in opt:
            if key in sys.argv:
                opt[key] = sys.argv[sys.argv.index(key) + 1]
        sizes = [int(v) for v in opt["--sizes"].split(",")]
        run_large(sizes, opt["--other"], int(opt["--sklearn-max"]))
        return

    if "--transfer-variants" in sys.argv:  # the transfer kernels' own bench
        import bench_gp_transfer

        sys.argv.remove("--transfer-variants")
        bench_gp_transfer.main()
        return
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="n = 50, 100 only")
    parser.add_argument(
        "--skip-sklearn-opt-above",
        type=int,
        default=10**9,
        help="skip scikit-learn's (slow) optimised fit for n above this",
    )
    parser.add_argument(
        "--single-thread",
        action="store_true",
        help="both sides on one thread (saved as gp-single-thread.json)",
    )
    args = parser.parse_args()
    n_jobs = 1 if args.single_thread else -1  # -1: every core (joblib's convention)
    limits = threadpool_limits(1) if args.single_thread else None
    sizes = [50, 100] if args.quick else [50, 100, 200, 400, 800]
    rows = []
    for d in (8, 22):
        for n in sizes:
            row = run(n, d, sklearn_opt=n <= args.skip_sklearn_opt_above, n_jobs=n_jobs)
            rows.append(row)
            print(row, flush=True)
    if not args.quick:
        rows.append(run(200, 15, sklearn_opt=True, n_jobs=n_jobs))
    cols = [
        "n",
        "d",
        "fixed ratio",
        "predict ratio",
        "opt ratio",
        "opt aptkt s",
        "opt sklearn s",
        "aptkt LML (sum)",
        "sklearn LML (sum)",
        "classes with LML >= sklearn",
        "aptkt acc",
        "sklearn acc",
        "fixed aptkt s",
        "fixed sklearn s",
        "predict aptkt s",
        "predict sklearn s",
    ]
    print(table(rows, cols))
    name = "gp-single-thread" if args.single_thread else "gp"
    print(
        "saved",
        save(name, {"rows": rows, "restarts": RESTARTS, "single_thread": args.single_thread}),
    )
    if limits is not None:
        limits.restore_original_limits()


if __name__ == "__main__":
    main()
