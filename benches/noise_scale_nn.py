"""How well single observations of the new objects tell them apart in each feature space:
nearest-neighbour accuracy with one training observation per new object (docs/experiments.md,
"The sensor's noise as the prior's scale").

    python benches/noise_scale_nn.py OUT [--draws 30] [--figure fig11|fig7]

OUT: a reproduction's output directory holding ``FIGURE/specs.jsonl``. For each setting (Fig. 11)
or prior group (Fig. 7) it takes the first APTKT run's priors, new objects, pool and test
trials, draws one pool observation per new object ``--draws`` times, and classifies the test
observations by their nearest training observation (Euclidean distance, each modality's columns
divided by √(its column count) so that modalities weigh alike) in three spaces: the prior's with
each column scaled by its spread over the old observations ("spread"), the prior's scaled by
the old objects' within-object noise ("noise"), and the new objects' own, fitted on the drawn
training observations (the baseline's). Per modality and for all modalities together; chance
is 1 / the number of new objects. A nearest neighbour, not the GP: it sees the metric each
space imposes without any hyper-parameters fitted on top.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from aptkt.experiments.runs import RunSpec, _table
from aptkt.learning import FeaturePipeline
from aptkt.learning.dataset import load_observations
from aptkt.learning.observations import Observations


def _features(pipe: FeaturePipeline, obs: Observations, modalities: list[str]) -> np.ndarray:
    X, cols = pipe.transform(obs)
    return np.hstack([X[:, cols[m]] / np.sqrt(len(cols[m])) for m in modalities])


def _nearest_accuracy(train: np.ndarray, labels, test: np.ndarray, truth) -> float:
    d = ((test[:, None, :] - train[None, :, :]) ** 2).sum(axis=-1)
    return float(np.mean(np.asarray(labels)[d.argmin(axis=1)] == np.asarray(truth)))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("output", type=Path)
    p.add_argument("--draws", type=int, default=30)
    p.add_argument("--figure", default="fig11", choices=("fig11", "fig7"))
    args = p.parse_args()
    lines = (args.output / args.figure / "specs.jsonl").read_text().splitlines()
    specs = [
        RunSpec.from_dict({k: v for k, v in json.loads(t).items() if k != "key"}) for t in lines
    ]
    firsts: dict[tuple, RunSpec] = {}
    for s in specs:
        if s.method == "APTKT" and s.tags.get("panel") != "stress":
            firsts.setdefault((s.tags.get("panel"), s.tags.get("group")), s)
    rng = np.random.default_rng(0)
    for (panel, group), spec in firsts.items():
        priors = spec.tags["priors"].split(",")
        pool = _table(spec.data, spec.new_objects, spec.pool_trials, spec.actions)
        test = _table(spec.data, spec.new_objects, spec.test_trials, spec.actions)
        old = load_observations(
            spec.data, actions=spec.actions, objects=priors, trials=spec.pool_trials
        )
        for a in spec.actions:
            spaces = {
                "spread": FeaturePipeline().fit(old[a]),
                "noise": FeaturePipeline().fit(old[a], scale="noise"),
            }
            names = list(pool[a].modality_names)
            cells = []
            for modalities in [[m] for m in names] + [names]:
                acc: dict[str, list[float]] = {"spread": [], "noise": [], "new": []}
                for _ in range(args.draws):
                    idx = np.array(
                        [rng.choice(np.flatnonzero(pool[a].objects == o)) for o in spec.new_objects]
                    )
                    train = pool[a].take(idx)
                    for name, pipe in {**spaces, "new": FeaturePipeline().fit(train)}.items():
                        acc[name].append(
                            _nearest_accuracy(
                                _features(pipe, train, modalities),
                                train.objects,
                                _features(pipe, test[a], modalities),
                                test[a].objects,
                            )
                        )
                label = "+".join(modalities)
                cells.append(
                    f"{label}: " + " ".join(f"{k} {np.mean(v):.2f}" for k, v in acc.items())
                )
            where = panel if args.figure == "fig11" else f"group {group}"
            print(f"{where} {a} ({', '.join(priors)}) | " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
