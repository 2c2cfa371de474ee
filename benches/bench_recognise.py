"""Latency of recognising one touch with a library — the robot decides between touches — and
the one-off cost of choosing the novelty threshold on the library.

Usage: python benches/bench_recognise.py [--objects 20] [--repeat 200]

A synthetic library in the shape of the BioTac benchmark's (27 columns in 4 modalities, one
action, 25 observations per object). Per touch: ``PriorKnowledge.recognise`` on one
observation (the library's feature transform, its identity model over every object and "new",
the fused posterior), wall time, median over ``--repeat`` touches, threshold cached. Peer, side
by side on the same features: scikit-learn's ``LinearDiscriminantAnalysis.predict_proba``
(a Gaussian classifier of the known objects only, no "none of them"), fitted on the library's
observations in its feature space.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from _common import save
from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

from aptkt.learning import PriorKnowledge
from aptkt.learning.observations import Observations

GROUPS = {"a": 3, "b": 2, "c": 3, "d": 19}


def observations(n_objects: int, n_per: int, seed: int, offset: int = 0) -> Observations:
    rng = np.random.default_rng(seed)
    d = sum(GROUPS.values())
    means = rng.normal(scale=2.5, size=(n_objects, d))
    X = np.concatenate([m + rng.normal(size=(n_per, d)) for m in means])
    objects = np.repeat([f"o{offset + k}" for k in range(n_objects)], n_per)
    mods, start = {}, 0
    for m, width in GROUPS.items():
        mods[m] = X[:, start : start + width]
        start += width
    return Observations("A", mods, objects, np.tile(np.arange(n_per), n_objects))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--objects", type=int, default=20)
    parser.add_argument("--repeat", type=int, default=200)
    args = parser.parse_args()
    library_obs = observations(args.objects, 25, 0)
    t0 = time.perf_counter()
    library = PriorKnowledge.build({"A": library_obs}, seed=0)
    build = time.perf_counter() - t0
    touches = observations(args.objects, 2, 0)  # the same objects, new touches
    t0 = time.perf_counter()
    library.recognise(touches.take(np.arange(1)))  # chooses and caches the threshold
    calibration = time.perf_counter() - t0
    ours = []
    for k in range(args.repeat):
        one = touches.take(np.array([k % len(touches)]))
        t0 = time.perf_counter()
        library.recognise(one)
        ours.append(time.perf_counter() - t0)
    ap = library["A"]
    X = ap.pipeline.transform(library_obs)[0]
    lda = LinearDiscriminantAnalysis().fit(X, library_obs.objects)
    T = ap.pipeline.transform(touches)[0]
    peer = []
    for k in range(args.repeat):
        t0 = time.perf_counter()
        lda.predict_proba(T[k % len(T)][None, :])
        peer.append(time.perf_counter() - t0)
    row = {
        "objects": args.objects,
        "per touch, median (ms)": 1e3 * statistics.median(ours),
        "per touch, 95th percentile (ms)": 1e3 * float(np.quantile(ours, 0.95)),
        "peer LDA per touch, median (ms)": 1e3 * statistics.median(peer),
        "ratio ours / peer": statistics.median(ours) / statistics.median(peer),
        "threshold on the library, once (s)": calibration,
        "library build (s)": build,
    }
    for k, v in row.items():
        print(f"{k}: {v:.3g}" if isinstance(v, float) else f"{k}: {v}")
    print(save(f"recognise-{args.objects}", {"repeat": args.repeat, **row}))


if __name__ == "__main__":
    main()
