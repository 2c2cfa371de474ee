"""A synthetic tactile world in feature space, built from plain arrays (no simulator).

Each object has a mean vector per (action, modality); observations scatter around it. New
objects are given related priors by placing their means near a chosen prior's mean.
"""

from __future__ import annotations

import numpy as np

from aptkt.learning import Observations
from aptkt.learning.pipeline import SKIN_EXTRACTION

ACTIONS = {"P1": {"force": 1, "thermal": 6}, "S1": {"texture": 5, "thermal": 6}}


def make_world(n_prior=3, n_new=3, related=True, noise=1.0, separation=1.6, seed=0):
    rng = np.random.default_rng(seed)
    priors = [f"old{i}" for i in range(n_prior)]
    news = [f"new{j}" for j in range(n_new)]
    means = {}
    for a, mods in ACTIONS.items():
        for o in priors:
            means[(a, o)] = {m: rng.normal(scale=separation * 3, size=d) for m, d in mods.items()}
        for j, o in enumerate(news):
            if related:
                base = means[(a, priors[j % n_prior])]
                means[(a, o)] = {m: v + rng.normal(scale=0.3, size=v.size) for m, v in base.items()}
            else:
                means[(a, o)] = {
                    m: rng.normal(scale=separation * 3, size=d) + 40.0 for m, d in mods.items()
                }
    return priors, news, means


def draw(means, objects, n_per, noise=1.0, seed=0):
    rng = np.random.default_rng(seed)
    table = {}
    for a, mods in ACTIONS.items():
        objs = np.repeat(objects, n_per)
        data = {
            m: np.concatenate(
                [means[(a, o)][m] + noise * rng.normal(size=(n_per, d)) for o in objects]
            )
            for m, d in mods.items()
        }
        table[a] = Observations(a, data, objs)
    return table


def as_skin(table):
    """The table's observations marked as this skin's features (as a data set's are), so that
    they get the skin's transforms: the regime of the tests that stand in for the skin."""
    for obs in table.values():
        obs.extraction = SKIN_EXTRACTION
    return table


#: The constructed one-action worlds of the feature-space tests: one action, one two-column
#: modality ("shape"), three old and three new objects.
SHAPE_ACTION = "A"
SHAPE_OLD = ["old0", "old1", "old2"]
SHAPE_NEW = ["new0", "new1", "new2"]


def shape_table(spec, n, seed):
    """``n`` observations of each object of ``spec`` (object -> (mean, noise sd per column))."""
    rng = np.random.default_rng(seed)
    rows, objects = [], []
    for o, (mean, sd) in spec.items():
        rows.append(np.asarray(mean) + np.asarray(sd) * rng.normal(size=(n, 2)))
        objects += [o] * n
    obs = Observations(SHAPE_ACTION, {"shape": np.concatenate(rows)}, np.array(objects))
    return {SHAPE_ACTION: obs}
