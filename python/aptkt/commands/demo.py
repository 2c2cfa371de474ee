"""``aptkt demo``: the README's main job."""

from __future__ import annotations

import argparse
import time

import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the end-to-end demo on the simulated world")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # Until the simulated world and the learner land, the demo exercises the numerical core:
    # a multi-modal Laplace GPC with and without transfer from a related source task.
    from aptkt.gp import LaplaceGPC, TransferSource

    rng = np.random.default_rng(args.seed)
    centers = rng.normal(scale=2.0, size=(5, 4))
    def draw(c, n):
        return centers[c] + rng.normal(size=(n, 4))
    X = np.concatenate([draw(c, 1) for c in range(5)])
    y = np.arange(5)
    X_test = np.concatenate([draw(c, 40) for c in range(5)])
    y_test = np.repeat(np.arange(5), 40)
    sources = {c: TransferSource(draw(c, 15), 0.8) for c in range(5)}
    kwargs = dict(modalities={"stiffness": [0], "texture": [1, 2], "thermal": [3]}, random_state=args.seed)
    t0 = time.perf_counter()
    plain = LaplaceGPC(**kwargs).fit(X, y)
    transfer = LaplaceGPC(**kwargs).fit(X, y, sources=sources)
    print("one observation per object, 5 objects, 3 modalities")
    print(f"  accuracy without transfer: {plain.score(X_test, y_test):.2f}")
    print(f"  accuracy with transfer   : {transfer.score(X_test, y_test):.2f}")
    print(f"  ({time.perf_counter() - t0:.2f} s)")
    return 0
