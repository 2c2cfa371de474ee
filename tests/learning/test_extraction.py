"""Observations remember what computed them, and only this skin's features, as this package
extracts them, get this skin's transforms by default: a modality of another sensor called
``texture`` or ``thermal`` is z-scored as it is."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.errors import InvalidInputError, PriorFileError
from aptkt.learning import (
    APTKT,
    FeaturePipeline,
    LearnerConfig,
    Observations,
    PoolEnvironment,
    PriorKnowledge,
)
from aptkt.learning.pipeline import SKIN_EXTRACTION

OBJECTS = ["a", "b", "c", "d"]


def _obs(extraction=None, n=6, seed=0, objects=OBJECTS):
    """Texture-like positive columns (activities) and a force column."""
    rng = np.random.default_rng(seed)
    names = np.repeat(objects, n)
    centre = {o: rng.uniform(1.0, 5.0, size=4) for o in objects}
    texture = np.array([centre[o] for o in names]) * rng.uniform(0.8, 1.2, size=(names.size, 4))
    force = rng.normal(size=(names.size, 1)) + np.arange(names.size)[:, None] % len(objects)
    return Observations(
        "S1",
        {"texture": texture, "force": force},
        names,
        np.tile(np.arange(n), len(objects)),
        extraction,
    )


def _logs(pipeline: FeaturePipeline) -> tuple[int, ...]:
    return pipeline.transforms["texture"].log_columns


def test_what_computed_the_observations_travels_with_them():
    obs = _obs(SKIN_EXTRACTION)
    assert obs.take(np.arange(3)).extraction == SKIN_EXTRACTION
    assert obs.of_objects(["a"]).extraction == SKIN_EXTRACTION
    one = Observations.single("S1", "a", obs.row(0), 0, SKIN_EXTRACTION)
    assert Observations.concat([obs, one]).extraction == SKIN_EXTRACTION
    # A part that does not say takes the others' word; two extractions are not pooled.
    assert Observations.concat([obs, _obs()]).extraction == SKIN_EXTRACTION
    assert Observations.concat([_obs(), _obs()]).extraction is None
    with pytest.raises(InvalidInputError, match="different extractions"):
        Observations.concat([obs, _obs("biotac")])
    with pytest.raises(InvalidInputError, match="extraction must be a name or None"):
        _obs("")


def test_only_this_skins_features_get_its_transforms_by_default():
    assert _logs(FeaturePipeline().fit(_obs(SKIN_EXTRACTION))) == (0, 1, 2)
    assert _logs(FeaturePipeline().fit(_obs())) == ()  # another sensor's "texture"
    assert _logs(FeaturePipeline().fit(_obs("biotac"))) == ()
    # Transforms given explicitly are used whatever the observations say.
    from aptkt.learning.pipeline import GENERIC_TRANSFORMS, SKIN_TRANSFORMS

    assert _logs(FeaturePipeline(SKIN_TRANSFORMS).fit(_obs())) == (0, 1, 2)
    assert _logs(FeaturePipeline(GENERIC_TRANSFORMS).fit(_obs(SKIN_EXTRACTION))) == ()


@pytest.mark.parametrize("extraction", [SKIN_EXTRACTION, None])
def test_a_prior_file_keeps_what_computed_its_observations(tmp_path, extraction):
    prior = PriorKnowledge.build({"S1": _obs(extraction)})
    assert _logs(prior["S1"].pipeline) == ((0, 1, 2) if extraction else ())
    loaded = PriorKnowledge.load(prior.save(tmp_path / "p.npz"))
    assert loaded["S1"].observations.extraction == extraction


@pytest.mark.parametrize("extractions", [{"P9": SKIN_EXTRACTION}, {"S1": ""}, ["S1"]])
def test_a_prior_file_with_bad_extractions_is_refused(tmp_path, extractions):
    import json

    path = PriorKnowledge.build({"S1": _obs(SKIN_EXTRACTION)}).save(tmp_path / "p.npz")
    with np.load(path) as z:
        arrays = dict(z.items())
    meta = json.loads(arrays["meta"].tobytes())
    assert meta["extractions"] == {"S1": SKIN_EXTRACTION}
    meta["extractions"] = extractions
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    bad = tmp_path / "bad.npz"
    np.savez_compressed(bad, **arrays)
    with pytest.raises(PriorFileError, match="'extractions' must map actions of the file"):
        PriorKnowledge.load(bad)


@pytest.mark.parametrize(("extraction", "logs"), [(SKIN_EXTRACTION, (0, 1, 2)), (None, ())])
def test_the_baseline_transforms_as_its_environment_observes(extraction, logs):
    """The baseline fits its transforms on the new objects' observations, which are computed
    as the environment says: a pool of this skin's features, or of any sensor's."""
    pool = {"S1": _obs(extraction, seed=1)}
    env = PoolEnvironment(pool, seed=0)
    assert env.extraction == extraction
    learner = APTKT(LearnerConfig(transfer="none", budget=2, seed=0))
    learner.run(env, ["S1"], OBJECTS)
    assert learner.learners["S1"].observations.extraction == extraction
    assert _logs(learner.learners["S1"]._pipeline()) == logs


def test_a_table_written_from_observations_says_what_they_say(tmp_path):
    from aptkt.learning.feature_table import read_feature_table, write_feature_table

    marked = write_feature_table(tmp_path / "skin.csv", {"S1": _obs(SKIN_EXTRACTION)})
    assert read_feature_table(marked).extraction == SKIN_EXTRACTION
    assert read_feature_table(marked).observations()["S1"].extraction == SKIN_EXTRACTION
    plain = write_feature_table(tmp_path / "other.h5", {"S1": _obs()})
    assert read_feature_table(plain).extraction is None
