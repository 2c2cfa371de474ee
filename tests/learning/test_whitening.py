"""The prior's feature space measured in the sensor's noise (``prior_feature_scale="whiten"``):
the old objects' between-object spread no longer sets the metric the new objects are judged in,
and noise correlated between columns is counted once."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.learning import (
    APTKT,
    GPSettings,
    LearnerConfig,
    PoolEnvironment,
    PriorKnowledge,
)

from .synthetic import SHAPE_ACTION as ACTION
from .synthetic import SHAPE_NEW as NEW
from .synthetic import SHAPE_OLD as OLD
from .synthetic import shape_table

# Unit noise in both columns for every object. The old objects lie far apart along column 1
# (±60) and together in column 0; the new objects lie 4 noise levels apart along column 1 and
# together in column 0. Scaled by the old objects' spread, column 1 is divided by ≈ 50 and the
# new objects' differences vanish under column 0's noise; scaled by the noise, they are 4 units.
OLD_MEANS = {o: (0.0, c) for o, c in zip(OLD, (-60.0, 0.0, 60.0))}
NEW_MEANS = {o: (0.0, c) for o, c in zip(NEW, (-4.0, 0.0, 4.0))}


def _table(means, n, seed):
    """Unit noise in both columns for every object."""
    return shape_table({o: (m, (1.0, 1.0)) for o, m in means.items()}, n, seed)


def _control_accuracy(scale: str, seed: int) -> float:
    """Mean accuracy over the curve of the prior's space without transfer (the control)."""
    prior = PriorKnowledge.build(
        _table(OLD_MEANS, 15, seed), gp=GPSettings(prior_feature_scale=scale), seed=seed
    )
    learner = APTKT(LearnerConfig(transfer="control", budget=4, seed=seed), prior)
    run = learner.run(
        PoolEnvironment(_table(NEW_MEANS, 8, seed + 1), seed=seed),
        [ACTION],
        NEW,
        _table(NEW_MEANS, 20, seed + 2),
    )
    return float(np.mean([s.mean_accuracy for s in run.steps]))


def test_the_noise_metric_keeps_what_the_spread_squeezes():
    spread = [_control_accuracy("spread", s) for s in range(3)]
    noise = [_control_accuracy("whiten", s) for s in range(3)]
    # 4 noise levels apart with 3 objects: a nearest-mean rule is right ≈ 95 % of the time.
    assert np.mean(noise) > 0.8
    assert np.mean(noise) > np.mean(spread) + 0.15


def test_the_prior_records_its_scale_and_the_transforms_hold_the_noise():
    table = _table(OLD_MEANS, 15, 0)
    noise = PriorKnowledge.build(table, gp=GPSettings(prior_feature_scale="whiten"), seed=0)
    spread = PriorKnowledge.build(table, gp=GPSettings(prior_feature_scale="spread"), seed=0)
    assert noise.metadata["gp"]["prior_feature_scale"] == "whiten"
    assert PriorKnowledge.build(table, seed=0).feature_scale == "whiten-joint"  # the default
    # Unit noise in each column; the spread of column 1 is that of the three clusters (≈ 49).
    assert noise[ACTION].pipeline.transforms["shape"].scale_ == pytest.approx([1, 1], rel=0.25)
    # Whitened: the old observations' residuals within each object have unit noise, and their
    # sample correlation (here noise, the true one is 0) is shrunk, never amplified.
    objects = table[ACTION].objects

    def residual_cov(Z):
        R = np.concatenate([Z[objects == o] - Z[objects == o].mean(axis=0) for o in OLD])
        return R.T @ R / (len(R) - len(OLD))

    white = residual_cov(noise[ACTION].pipeline.transform(table[ACTION])[0])
    raw = residual_cov(table[ACTION].modalities["shape"])
    raw_corr = raw[0, 1] / np.sqrt(raw[0, 0] * raw[1, 1])
    np.testing.assert_allclose(np.diag(white), [1.0, 1.0], atol=0.2)
    assert abs(white[0, 1]) <= abs(raw_corr) + 1e-12
    assert spread[ACTION].pipeline.transforms["shape"].scale_[1] > 40
    with pytest.raises(ValueError, match="prior_feature_scale"):
        GPSettings(prior_feature_scale="total")


def test_a_prior_knows_its_scale_through_files_subsets_and_inspect(tmp_path, capsys):
    table = _table(OLD_MEANS, 15, 0)
    spread = PriorKnowledge.build(table, gp=GPSettings(prior_feature_scale="spread"), seed=0)
    path = spread.save(tmp_path / "spread.npz")
    loaded = PriorKnowledge.load(path)
    assert loaded.feature_scale == "spread"
    # A subset is rebuilt with the source's scale, not the default's.
    sub = loaded.subset(OLD[:2])
    assert sub.feature_scale == "spread"
    assert sub[ACTION].pipeline.transforms["shape"].scale_[1] > 20  # two clusters 60 apart
    assert PriorKnowledge.build(table, seed=0).subset(OLD[:2]).feature_scale == "whiten-joint"
    # Files written before the setting existed carry no such field: they used the spread.
    del loaded.metadata["gp"]["prior_feature_scale"]
    assert loaded.feature_scale == "spread"
    assert main(["prior", "inspect", str(path)]) == 0
    assert "each column z-scored over the old objects' observations" in capsys.readouterr().out
