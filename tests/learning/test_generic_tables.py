"""This skin's feature transforms (log of the texture activities, PCA of the thermal curve)
apply to this skin's data or when asked for, never to another sensor's table because one of
its groups happens to be called ``texture`` or ``thermal``."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.errors import ConfigError
from aptkt.experiments.own_data import compare_on_data
from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge
from aptkt.learning.library import merge_priors
from aptkt.learning.pipeline import (
    GENERIC_TRANSFORMS,
    SKIN_TRANSFORMS,
    FeaturePipeline,
    ModalityTransform,
)

from .synthetic import ACTIONS, as_skin, draw, make_world


def _rows(seed=0):
    rng = np.random.default_rng(seed)
    rows = {"object": [], "action": [], "trial": [], "vib_rms": [], "fx": [], "fy": []}
    for k, o in enumerate("abcd"):
        for t in range(6):
            rows["object"].append(o)
            rows["action"].append("press")
            rows["trial"].append(t)
            rows["vib_rms"].append(1.0 + k + 0.3 * rng.normal())
            rows["fx"].append(k + 0.3 * rng.normal())
            rows["fy"].append(-k + 0.3 * rng.normal())
    return rows


def test_a_generic_group_called_texture_gets_no_transform(tmp_path):
    """It ended in IndexError: the skin's log of texture columns 0-2 met a one-column group."""
    rows = _rows()
    result = compare_on_data(
        rows,
        modalities={"texture": ["vib_rms"], "force": ["fx", "fy"]},
        prior_objects=["a", "b"],
        new_objects=["c", "d"],
        runs=1,
        budget=1,
        output=tmp_path / "out",
    )
    assert set(result.accuracy) == {"APTKT", "APTKT+aux", "baseline"}
    texture = PriorKnowledge.load(tmp_path / "out" / "prior.npz")["press"].pipeline.transforms[
        "texture"
    ]
    assert texture.log_columns == () and texture.pca_components is None
    # Up to the usual scaling the feature reaches the model as it is: an affine map of it.
    raw = np.array(rows["vib_rms"])[:, None]
    out = texture.transform(raw)[:, 0]
    slope, intercept = np.polyfit(raw[:, 0], out, 1)
    np.testing.assert_allclose(out, slope * raw[:, 0] + intercept, atol=1e-9)


def test_the_skins_own_data_keeps_its_transforms():
    priors, news, means = make_world(n_prior=2, n_new=2, seed=1)
    pool = as_skin(draw(means, news, 3, seed=2))
    prior = PriorKnowledge.build(as_skin(draw(means, priors, 6, seed=1)), seed=0)
    assert prior["S1"].pipeline.transforms["texture"].log_columns == (0, 1, 2)
    assert prior["P1"].pipeline.transforms["thermal"].components_ is not None
    for transforms, log_columns in ((None, (0, 1, 2)), (GENERIC_TRANSFORMS, ())):
        learner = APTKT(LearnerConfig(transfer="none", budget=0), transforms=transforms)
        learner.run(PoolEnvironment(pool, seed=0), list(ACTIONS), news)
        baseline = learner.learners["S1"]._pipeline()
        assert baseline.transforms["texture"].log_columns == log_columns


def test_a_skin_transform_asked_for_on_a_narrower_modality_is_a_typed_error():
    X = np.arange(6.0).reshape(6, 1) + 1
    with pytest.raises(ConfigError, match="columns \\[0, 1, 2\\] of a modality of 1 column"):
        ModalityTransform(log_columns=(0, 1, 2)).fit(X)
    assert FeaturePipeline(SKIN_TRANSFORMS).transforms.keys() == SKIN_TRANSFORMS.keys()
    assert FeaturePipeline().transforms == {}  # chosen when fitted, by what the data says


def test_merging_keeps_each_librarys_transforms():
    """A library built from a table (no skin transforms) stays so when merged, and the skin's
    stays the skin's: the merge refits with the first library's transforms."""
    priors, _, means = make_world(n_prior=4, n_new=0, seed=1)
    table = as_skin(draw(means, priors, 6, seed=1))
    halves = [{a: o.of_objects(priors[:2]) for a, o in table.items()}]
    halves.append({a: o.of_objects(priors[2:]) for a, o in table.items()})
    for transforms, log_columns in ((GENERIC_TRANSFORMS, ()), (None, (0, 1, 2))):
        parts = [PriorKnowledge.build(h, seed=0, transforms=transforms) for h in halves]
        merged = merge_priors([("a", parts[0]), ("b", parts[1])])
        assert merged["S1"].pipeline.transforms["texture"].log_columns == log_columns
