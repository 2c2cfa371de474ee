import numpy as np
import pytest


def make_blobs(n_per_class, n_classes, d, spread=1.0, seed=0):
    rng = np.random.default_rng(seed)
    centers = rng.normal(scale=2.0, size=(n_classes, d))
    X = np.concatenate([c + spread * rng.normal(size=(n_per_class, d)) for c in centers])
    y = np.repeat(np.arange(n_classes), n_per_class)
    return X, y


@pytest.fixture
def blobs():
    return make_blobs
