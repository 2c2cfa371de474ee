"""The noise profile against data whose separation, drift and heterogeneity are known."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.experiments.noise_profile import noise_profile
from aptkt.learning import Observations

N_OBJECTS, N_TRIALS = 40, 30


def _table(drift=0.0, spread_of_noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    objects = np.repeat([f"o{k}" for k in range(N_OBJECTS)], N_TRIALS)
    trials = np.tile(np.arange(N_TRIALS), N_OBJECTS)
    means = np.repeat(rng.normal(0.0, 3.0, size=(N_OBJECTS, 2)), N_TRIALS, axis=0)
    sd = np.repeat(np.exp(rng.normal(0.0, spread_of_noise, size=(N_OBJECTS, 1))), N_TRIALS, axis=0)
    X = means + sd * rng.normal(size=(objects.size, 2)) + drift * (trials / N_TRIALS)[:, None]
    # Shuffle the rows: the profile must order each object's trials itself.
    order = rng.permutation(objects.size)
    return {"A": Observations("A", {"m": X[order]}, objects[order], trials[order])}


def test_stationary_equal_noise_reads_as_one():
    (p,) = noise_profile(_table())
    assert p.action == "A" and p.modality == "m" and p.columns == 2
    assert p.separation == pytest.approx(3.0, rel=0.2)
    assert p.drift == pytest.approx(1.0, abs=0.2)
    assert p.heterogeneity == pytest.approx(1.0, abs=0.25)


def test_drift_and_unequal_noise_are_seen_as_such():
    (drifting,) = noise_profile(_table(drift=3.0))
    assert drifting.drift > 3.0
    (unequal,) = noise_profile(_table(spread_of_noise=0.5))
    assert unequal.heterogeneity > 3.0 and unequal.drift == pytest.approx(1.0, abs=0.3)
