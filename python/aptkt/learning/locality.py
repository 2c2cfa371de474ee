"""What a library of any size gives a new object, at a cost that does not grow with the library.

A library carries over two kinds of knowledge, and neither needs every old object at once:

* **What is a property of the sensor and the action** — the metric (the within-object noise),
  the identity model's noise and spread, the kernel's amplitude and length-scale. The metric
  and the identity model are sums over the observations (cheap at any size, and exact). The
  kernel is learned by Laplace GP classifiers whose cost grows with the cube of their rows; it
  is a property of the sensor, which a few objects' repeated observations pin down as well as
  a thousand do. So it is learned on the **kernel sample**: objects drawn at random, as many as
  :data:`LOCAL_OBJECTS` objects and :data:`LOCAL_ROWS` observations hold.
* **What a new object needs of particular old objects** — which old object it is most like
  (Eq. 3), the source task a transfer couples it to (Eq. 2), the old models' posteriors
  (Eq. 5) — involves only the old objects near it, because the kernel between observations
  several length-scales apart vanishes. Each old object's one-vs-all classifier is fitted on its
  **neighbourhood**: the object and the library's objects nearest to it under the identity
  model, as many as the same limits hold; a new object is compared with its
  :data:`CANDIDATES` nearest old objects (again under the identity model), each judged by its
  own classifier.

A library within the limits is its own kernel sample and every neighbourhood is the whole
library: the models are exactly the ones of ``GPSettings(library_model="exact")``, which fits
every classifier on every old observation (its cost grows as N⁴ in the number of objects N: a
library of 100 objects takes minutes and 5 GB; docs/method.md). Beyond the limits, what is
approximated is only the reach of each classifier — the old objects that do not fit a
neighbourhood are left out of it — and the sample the kernel is learned on.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["CANDIDATES", "LOCAL_OBJECTS", "LOCAL_ROWS", "kernel_sample", "take_objects"]

#: At most this many objects, and this many of their observations, make up the kernel sample and
#: each old object's neighbourhood: the size at which one Laplace fit of a one-vs-all model
#: costs about a second on one core (and the largest library the real-data benchmark holds: 15
#: materials × 25 trials, which therefore learns exactly as with every observation).
LOCAL_OBJECTS = 16
LOCAL_ROWS = 400
#: A new object is compared (Eq. 3) with this many old objects: the most likely, under the
#: library's identity model, to have given its observations.
CANDIDATES = 8


def take_objects(
    order: Sequence[int] | np.ndarray,
    rows_by_object: Sequence[np.ndarray],
    most_objects: int = LOCAL_OBJECTS,
    most_rows: int = LOCAL_ROWS,
) -> np.ndarray:
    """The rows of the objects of ``order`` (indices into ``rows_by_object``), taken in that
    order while at most ``most_objects`` objects and ``most_rows`` rows are taken — at least
    two objects, whose rows are thinned evenly where two alone exceed ``most_rows``. Sorted."""
    chosen: list[int] = []
    total = 0
    for k in order:
        n = int(rows_by_object[k].size)
        if len(chosen) >= 2 and (len(chosen) >= most_objects or total + n > most_rows):
            break
        chosen.append(int(k))
        total += n
    if total > most_rows:
        share = most_rows // len(chosen)
        parts = []
        for k in chosen:
            rows = rows_by_object[k]
            take = min(rows.size, share)
            parts.append(rows[np.linspace(0, rows.size - 1, take).round().astype(np.int64)])
        return np.sort(np.concatenate(parts))
    return np.sort(np.concatenate([rows_by_object[k] for k in chosen]))


def rows_by_object(objects: np.ndarray) -> tuple[list[str], list[np.ndarray]]:
    """The sorted object names of ``objects`` (one per row) and each one's row indices."""
    labels = np.asarray(objects).astype(str)
    names, index = np.unique(labels, return_inverse=True)
    order = np.argsort(index, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(np.bincount(index, minlength=names.size))])
    return [str(n) for n in names], [order[bounds[k] : bounds[k + 1]] for k in range(names.size)]


def kernel_sample(objects: np.ndarray, seed: int) -> np.ndarray:
    """The rows the library's kernel is learned on: every row if the library is within the
    limits, else the objects of a random order (seeded by ``seed``) while the limits hold."""
    names, rows = rows_by_object(objects)
    if len(names) <= LOCAL_OBJECTS and len(objects) <= LOCAL_ROWS:
        return np.arange(len(objects))
    order = np.random.default_rng(seed).permutation(len(names))
    return take_objects(order, rows)
