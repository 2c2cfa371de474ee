"""The method on the simulated world with fixed seeds (issue: transfer helps early; unrelated
priors do not hurt beyond noise). The data are simulated here (about 220 recordings)."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.actions import PAPER_ACTIONS
from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge
from aptkt.learning.dataset import load_observations
from aptkt.runtime.generation import GenerationPlan, generate

pytestmark = pytest.mark.slow

ACTIONS = ("P2", "S4", "C1")  # one of each movement, the cheapest to simulate
NEW = ("smooth_sponge", "hard_box", "biscuit_box", "mouse_pad", "bamboo_board")
RELATED = ("rough_sponge", "paper_box", "metal_toolbox")  # paper §5.1 relations
UNRELATED = ("ceramic_tile", "cork_board", "plastic_container")
SEEDS = range(20)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    path = tmp_path_factory.mktemp("sim") / "sim.h5"
    acts = tuple(PAPER_ACTIONS[a] for a in ACTIONS)
    generate(path, GenerationPlan(RELATED + UNRELATED, acts, 6, seed=0), jobs=2, progress=False)
    generate(path, GenerationPlan(NEW, acts, 11, seed=0), jobs=2, resume=True, progress=False)
    return path


def curves(data, priors):
    prior = PriorKnowledge.build(load_observations(data, actions=ACTIONS, objects=priors), seed=0)
    pool = load_observations(data, actions=ACTIONS, objects=NEW, trials=range(5))
    test = load_observations(data, actions=ACTIONS, objects=NEW, trials=range(5, 11))
    methods = {
        "baseline": dict(transfer="none"),
        "APTKT": dict(transfer="paper"),
        "APTKT+aux": dict(transfer="paper", auxiliary=True),
    }
    out = {}
    for name, kw in methods.items():
        runs = [
            APTKT(LearnerConfig(budget=3, seed=s, **kw), prior)
            .run(PoolEnvironment(pool, seed=s), ACTIONS, NEW, test)
            .curve()["mean_accuracy"]
            for s in SEEDS
        ]
        out[name] = np.array(runs)
    return out


def test_transfer_from_related_priors_helps_early(data):
    c = curves(data, RELATED)
    base, plain, aux = (c[k].mean() for k in ("baseline", "APTKT", "APTKT+aux"))
    # Mean accuracy over the first four learning steps (the initial round and three more), 20 runs.
    assert aux > base + 0.015, (base, plain, aux)
    assert plain > base - 0.02, (base, plain, aux)


def test_unrelated_priors_do_not_hurt(data):
    c = curves(data, UNRELATED)
    base, plain = c["baseline"].mean(), c["APTKT"].mean()
    assert plain > base - 0.02, (base, plain)
