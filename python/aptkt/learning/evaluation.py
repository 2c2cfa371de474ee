"""Accuracy of the observation models on held-out test observations (docs/design.md §5)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = ["accuracy", "fused_accuracy"]


def accuracy(posteriors: np.ndarray, classes: Sequence[str], truth: Sequence[str]) -> float:
    """Fraction of rows whose most probable class is the true one."""
    p = np.asarray(posteriors)
    if p.shape[0] == 0:
        raise InvalidInputError("no test observations")
    predicted = np.asarray(classes)[np.argmax(p, axis=1)]
    return float(np.mean(predicted == np.asarray(truth)))


def fused_accuracy(
    posteriors: Mapping[str, np.ndarray],
    truth: Mapping[str, np.ndarray],
    classes: Sequence[str],
) -> float:
    """Accuracy of combining the actions' posteriors as independent evidence.

    For each object, the k-th test observation of every action forms one multi-action sample;
    its fused posterior is the normalised product of the actions' posteriors (a sum of logs).
    Objects contribute as many samples as their scarcest action has test observations.
    """
    actions = list(posteriors)
    if not actions:
        raise InvalidInputError("no actions to fuse")
    classes = list(classes)
    correct = total = 0
    for obj in classes:
        rows = {a: np.flatnonzero(np.asarray(truth[a]) == obj) for a in actions}
        k = min(len(r) for r in rows.values())
        if k == 0:
            continue
        log_post = np.zeros((k, len(classes)))
        for a in actions:
            log_post += np.log(np.clip(posteriors[a][rows[a][:k]], 1e-300, None))
        correct += int(np.sum(np.argmax(log_post, axis=1) == classes.index(obj)))
        total += k
    if total == 0:
        raise InvalidInputError("no object has test observations for every action")
    return correct / total
