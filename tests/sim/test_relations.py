"""The simulated world's designed relations hold in the features the learner sees.

Every new object of the package's library declares in ``objects.toml`` which prior it is
designed to resemble, in which modality and for which actions. Here each object is explored a
few times with the real simulator and feature extraction; the feature pipeline is fitted on the
prior objects' observations (the prior knowledge's feature space) and the new object's mean
observation must lie nearest to its designed relative's. The presses' force must also grow with
depth differently for different objects (soft layers on hard ones lock up).

The relations are properties of the objects, so they are measured without the recording's
sessions and drift (``RecordingDrift.off()``) and at the physical noise level: in the default
world the new objects are recorded in another session than the priors, whose room and skin
calibration move every new object's observations away from the priors' (docs/simulation.md,
"Sessions and drift"), and its noise is fitted to a real sensor's ("Noise fitted to a table").
"""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.actions import PAPER_ACTIONS
from aptkt.learning.extract import observations_from_recordings
from aptkt.learning.pipeline import FeaturePipeline
from aptkt.sim import RecordingDrift, SimWorld
from aptkt.sim.noise import PHYSICAL
from aptkt.sim.objects import default_library

pytestmark = pytest.mark.slow

#: Trials per object and action: enough for a stable mean, few enough to stay cheap.
TRIALS = 3  # trials 0-2, as the tables of docs/simulation.md


@pytest.fixture(scope="module")
def world_features():
    lib = default_library()
    priors, new = lib.with_role("prior"), lib.with_role("new")
    actions = {"P1", "P2"} | {a for o in new for r in lib[o].relations for a in r.actions}
    world = SimWorld(lib, seed=0, drift=RecordingDrift.off(), noise=PHYSICAL)
    out = {}
    for a in sorted(actions):
        objects = priors + [o for o in new if a in {"P1", "P2"} or _uses(lib[o], a)]
        recs = [(o, t, world.explore(o, a, t)) for o in objects for t in range(TRIALS)]
        obs = observations_from_recordings(PAPER_ACTIONS[a], recs)
        is_prior = np.isin(obs.objects, priors)
        pipe = FeaturePipeline().fit(obs.take(np.flatnonzero(is_prior)))
        X, groups = pipe.transform(obs)
        means = {o: X[obs.objects == o].mean(axis=0) for o in objects}
        force = obs.modalities.get("force")
        forces = (
            None if force is None else {o: float(force[obs.objects == o].mean()) for o in objects}
        )
        out[a] = (means, groups, forces)
    return lib, priors, out


def _uses(obj, action):
    return any(action in r.actions for r in obj.relations)


def _distance(a: np.ndarray, b: np.ndarray, groups, modality: str) -> float:
    """Squared distance in one modality's columns; for ``"all"`` the sum over modalities of the
    mean squared difference per column, so that each modality weighs the same."""
    if modality != "all":
        cols = groups[modality]
        return float(np.sum((a[cols] - b[cols]) ** 2))
    return float(sum(np.mean((a[c] - b[c]) ** 2) for c in groups.values()))


def test_every_new_object_has_a_designed_relation():
    lib = default_library()
    for name in lib.with_role("new"):
        rels = lib[name].relations
        assert rels, name
        for r in rels:
            assert lib[r.prior].role == "prior" and r.why
            assert set(r.actions) <= set(PAPER_ACTIONS)
            for a in r.actions:
                assert r.modality == "all" or r.modality in PAPER_ACTIONS[a].modalities


def test_designed_relative_is_the_nearest_prior(world_features):
    lib, priors, per_action = world_features
    failures = []
    for name in lib.with_role("new"):
        for rel in lib[name].relations:
            for a in rel.actions:
                means, groups, _ = per_action[a]
                d = {p: _distance(means[name], means[p], groups, rel.modality) for p in priors}
                nearest = min(d, key=d.get)
                if nearest != rel.prior:
                    failures.append(
                        f"{name} {a} {rel.modality}: nearest {nearest} ({d[nearest]:.3f}), "
                        f"designed {rel.prior} ({d[rel.prior]:.3f})"
                    )
    assert not failures, "\n".join(failures)


def test_force_grows_with_depth_differently_across_objects(world_features):
    lib, _, per_action = world_features
    f1, f2 = per_action["P1"][2], per_action["P2"][2]
    ratio = {o: f2[o] / f1[o] for o in lib}
    # Objects much stiffer than the skin, or soft and linear, double their force from 1 to 2 mm;
    # a thin soft layer on a hard base locks up within the deeper press and more than doubles it.
    soft_on_hard = ("padded_case", "mouse_pad")
    others = [o for o in lib if o not in soft_on_hard]
    assert min(ratio[o] for o in soft_on_hard) > max(ratio[o] for o in others), ratio
    assert max(ratio.values()) / min(ratio.values()) > 1.25, ratio
    # At 1 mm the soft-on-hard objects are among the softest; at 2 mm stiffer than the sponges.
    for o in soft_on_hard:
        assert f1[o] < 0.6 * f1["ceramic_tile"]
        assert f2[o] > 1.3 * max(f2["rough_sponge"], f2["smooth_sponge"])
    # The new objects span distinct stiffness: P2 forces of at least three well-separated levels.
    levels = sorted(f2[o] for o in lib.with_role("new"))
    assert levels[-1] > 2.5 * levels[0]
