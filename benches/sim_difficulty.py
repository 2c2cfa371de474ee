"""How hard is the simulated world? Per-action object classification with a simple classifier.

For every action, features per recording (paper §3.2): stiffness F̄ (press, static contact),
texture descriptor TD (slides), and the thermal curve [T̄, ∇T̄] reduced by PCA (10 dims, fitted
on the training split only, scaled as a whole). Features are standardised on the training
split and each modality gets the same weight in the distance; a k-NN
classifier (k = 3) is trained on 10 observations per object and tested on the others;
random splits are repeated. Reported: accuracy over all 15 objects and over the 5 new objects
only, per modality and combined.

    python benches/sim_difficulty.py DATA.h5 [--splits 20] [--json OUT]
    aptkt dataset generate -o DATA.h5 -n 20 -j 2      # the paper's test set
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict

import numpy as np

from aptkt import features as F
from aptkt.actions import Movement
from aptkt.data import DatasetReader
from aptkt.sim.objects import default_library

RATE = 250.0
THERMAL_POINTS = 50  # T̄ resampled to this many steps before [T̄, ∇T̄]


def recording_features(rec) -> dict[str, np.ndarray]:
    """Modality → feature vector for one recording."""
    meta = rec.metadata
    movement = Movement(meta["action"]["movement"])
    out: dict[str, np.ndarray] = {}
    temp = rec.grid("temp", RATE)[:, :, 1]  # (cells, steps): the LM71s
    idx = np.linspace(0, temp.shape[1] - 1, THERMAL_POINTS).round().astype(int)
    out["thermal"] = F.thermal_curve(temp[:, idx])
    if movement is Movement.SLIDE:
        acc = rec.grid("acc", RATE).transpose(0, 2, 1)  # (cells, 3, steps)
        out["texture"] = F.texture_descriptor(acc)
    else:
        out["force"] = np.array([F.mean_force(rec.grid("force", RATE))])
    return out


def load(path: str) -> dict[str, dict]:
    """action → {'objects': [...], 'X': {modality: (n, d)}}"""
    data: dict[str, dict] = defaultdict(lambda: {"objects": [], "X": defaultdict(list)})
    with DatasetReader(path) as rd:
        for i in range(len(rd)):
            obj, action, _ = rd.key(i)
            feats = recording_features(rd.recording(i))
            d = data[action]
            d["objects"].append(obj)
            for m, v in feats.items():
                d["X"][m].append(v)
    return {
        a: {"objects": np.array(d["objects"]), "X": {m: np.array(v) for m, v in d["X"].items()}}
        for a, d in data.items()
    }


def _prepare(X: dict[str, np.ndarray], train: np.ndarray, test: np.ndarray, modalities: list[str]):
    from sklearn.decomposition import PCA
    from sklearn.preprocessing import StandardScaler

    parts_tr, parts_te = [], []
    for m in modalities:
        a, b = X[m][train], X[m][test]
        if m == "thermal":
            # PCA keeps the components' relative variances (as an isotropic kernel on them
            # would see them): one common scale for the whole modality.
            pca = PCA(n_components=min(10, a.shape[0] - 1, a.shape[1])).fit(a)
            a, b = pca.transform(a), pca.transform(b)
            scale = np.sqrt(np.sum(pca.explained_variance_))
            a, b = a / scale, b / scale
        else:
            sc = StandardScaler().fit(a)
            a, b = sc.transform(a) / np.sqrt(a.shape[1]), sc.transform(b) / np.sqrt(a.shape[1])
        # Each modality gets the same total weight in the distance, whatever its dimension.
        parts_tr.append(a)
        parts_te.append(b)
    return np.hstack(parts_tr), np.hstack(parts_te)


def _classifier(name: str, k: int):
    if name == "gpc":
        from sklearn.gaussian_process import GaussianProcessClassifier
        from sklearn.gaussian_process.kernels import RBF, ConstantKernel

        return GaussianProcessClassifier(
            ConstantKernel(1.0) * RBF(1.0), n_restarts_optimizer=0, random_state=0
        )
    from sklearn.neighbors import KNeighborsClassifier

    return KNeighborsClassifier(n_neighbors=k)


def evaluate(
    data: dict,
    objects: list[str],
    per_object: int,
    splits: int,
    k: int,
    seed: int,
    classifier: str = "knn",
) -> dict:
    rng = np.random.default_rng(seed)
    results = {}
    for action, d in sorted(data.items()):
        y = d["objects"]
        keep = np.isin(y, objects)
        yk = y[keep]
        X = {m: v[keep] for m, v in d["X"].items()}
        modalities = sorted(X)
        combos = {m: [m] for m in modalities}
        combos["multi"] = modalities
        acc = {name: [] for name in combos}
        for _ in range(splits):
            train = np.zeros(yk.size, bool)
            for o in objects:
                idx = np.flatnonzero(yk == o)
                train[rng.choice(idx, size=min(per_object, idx.size - 1), replace=False)] = True
            test = ~train
            for name, mods in combos.items():
                a, b = _prepare(X, train, test, mods)
                clf = _classifier(classifier, k).fit(a, yk[train])
                acc[name].append(float(np.mean(clf.predict(b) == yk[test])))
        results[action] = {name: float(np.mean(v)) for name, v in acc.items()}
    return results


def confusion(
    data: dict, action: str, objects: list[str], per_object: int, seed: int
) -> np.ndarray:
    from sklearn.neighbors import KNeighborsClassifier

    rng = np.random.default_rng(seed)
    d = data[action]
    y = d["objects"]
    keep = np.isin(y, objects)
    yk = y[keep]
    X = {m: v[keep] for m, v in d["X"].items()}
    train = np.zeros(yk.size, bool)
    for o in objects:
        idx = np.flatnonzero(yk == o)
        train[rng.choice(idx, size=min(per_object, idx.size - 1), replace=False)] = True
    a, b = _prepare(X, train, ~train, sorted(X))
    pred = KNeighborsClassifier(n_neighbors=3).fit(a, yk[train]).predict(b)
    cm = np.zeros((len(objects), len(objects)), int)
    pos = {o: i for i, o in enumerate(objects)}
    for t, p in zip(yk[~train], pred):
        cm[pos[t], pos[p]] += 1
    return cm


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("data")
    ap.add_argument("--splits", type=int, default=20)
    ap.add_argument("--train", type=int, default=10, help="training observations per object")
    ap.add_argument("-k", type=int, default=3)
    ap.add_argument(
        "--classifier",
        choices=("knn", "gpc"),
        default="knn",
        help="k-NN, or scikit-learn's GaussianProcessClassifier (RBF, one-vs-rest, fitted hyper-parameters)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", metavar="OUT")
    ap.add_argument("--confusion", metavar="ACTION", action="append", default=[])
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    data = load(args.data)
    lib = default_library()
    everything = [o for o in lib if any(o in d["objects"] for d in data.values())]
    new = [o for o in lib.with_role("new") if o in everything]
    res_all = evaluate(
        data, everything, args.train, args.splits, args.k, args.seed, args.classifier
    )
    res_new = evaluate(data, new, args.train, args.splits, args.k, args.seed, args.classifier)
    clf = f"k-NN (k={args.k})" if args.classifier == "knn" else "GPC (RBF, one-vs-rest)"
    print(
        f"features of {sum(len(d['objects']) for d in data.values())} recordings, {time.perf_counter() - t0:.1f} s; "
        f"{clf}, {args.train} training observations per object, {args.splits} random splits"
    )
    for label, res, n in (
        ("all objects", res_all, len(everything)),
        ("new objects", res_new, len(new)),
    ):
        print(f"\n{label} ({n}, chance {100 / n:.0f} %)")
        names = sorted({m for r in res.values() for m in r})
        print("action  " + "".join(f"{m:>9}" for m in names))
        for action, r in res.items():
            print(
                f"{action:6s}  "
                + "".join(f"{100 * r[m]:8.1f}%" if m in r else f"{'':9}" for m in names)
            )
        print(
            "mean    "
            + "".join(
                f"{100 * np.mean([r[m] for r in res.values() if m in r]):8.1f}%" for m in names
            )
        )
    for action in args.confusion:
        cm = confusion(data, action, everything, args.train, args.seed)
        print(f"\nconfusion {action} (rows true, columns predicted):")
        for o, row in zip(everything, cm):
            print(f"  {o:18s} " + " ".join(f"{v:2d}" for v in row))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"all": res_all, "new": res_new}, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
