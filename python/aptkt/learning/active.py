"""Choosing the next (action, object) pair to observe (:data:`SELECTIONS`).

- ``"error-reduction"`` (the default, beyond the paper): the pair whose next touch is expected
  to remove the most error — expected error reduction (Roy and McCallum 2001) for a learner
  that chooses the object, and so knows the label of what it will read. The model's error on
  a pair's touches is estimated by the posterior mass its model gives other objects on that
  pair's observations (:func:`own_error`); an object's region of the feature space is known to
  within noise/√n after n touches, so its error falls as 1/n, and one more touch removes the
  share ``1/(n + 1)`` of it (:func:`expected_error_reduction`). The score is largest for
  objects that are confused *and* seldom touched: a pair already touched often teaches less
  with every touch, which AT-LPP does not see.
- ``"paper"``: AT-LPP (paper §4.7, Eq. 4). ``UNC(α, c_j)`` is the mean Shannon entropy of the
  new-object posterior over the observations collected so far for action α on object c_j; the
  pair with the largest uncertainty is explored next.
- ``"random"``: uniformly random picks (Eq. 4 with ε_explor = 1), the reference.

With probability ``ε_explor`` the first two draw the pair uniformly instead.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = [
    "SELECTIONS",
    "entropy",
    "uncertainty",
    "own_error",
    "expected_error_reduction",
    "Selection",
    "select_next",
]

Pair = tuple[str, str]

#: The selection rules, by the name the command line and the configuration use.
SELECTIONS = ("error-reduction", "paper", "random")


def entropy(posteriors: np.ndarray) -> np.ndarray:
    """Shannon entropy (nats) of each row of a probability matrix; 0 log 0 = 0."""
    p = np.asarray(posteriors, dtype=np.float64)
    if p.ndim != 2:
        raise InvalidInputError(f"expected a 2-D array of posteriors, got shape {p.shape}")
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where(p > 0, -p * np.log(p), 0.0)
    return terms.sum(axis=1)


def uncertainty(posteriors: np.ndarray) -> float:
    """UNC of one (action, object) pair: the mean entropy over its observations."""
    h = entropy(posteriors)
    if h.size == 0:
        raise InvalidInputError("UNC needs at least one observation")
    return float(h.mean())


def own_error(posteriors: np.ndarray, column: int) -> float:
    """The model's error on one pair's observations: the mean posterior mass it gives the other
    objects (``posteriors``: one row per observation of the object whose column is
    ``column``)."""
    p = np.asarray(posteriors, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] == 0:
        raise InvalidInputError(f"expected posteriors of at least one observation, got {p.shape}")
    if not 0 <= column < p.shape[1]:
        raise InvalidInputError(f"column {column} is not among the {p.shape[1]} classes")
    return float(np.clip(1.0 - p[:, column].mean(), 0.0, 1.0))


def expected_error_reduction(error: float, count: int) -> float:
    """The error one more touch removes from a pair whose error is ``error`` after ``count``
    touches, where error falls as 1/n: ``e/n·n − e·n/(n + 1) = e/(n + 1)``."""
    if count < 1:
        raise InvalidInputError(f"a pair's error needs at least one touch, got {count}")
    return float(error) / (count + 1)


@dataclass(frozen=True)
class Selection:
    """The pair chosen, whether it was drawn at random, and the rule's score of it (AT-LPP:
    its uncertainty; error reduction: the error it is expected to remove)."""

    action: str
    object: str
    explored: bool
    score: float


def select_next(
    scores: Mapping[Pair, float],
    actions: Sequence[str],
    objects: Sequence[str],
    eps_explor: float,
    rng: np.random.Generator,
    available: Sequence[Pair] | None = None,
) -> Selection:
    """Eq. 4 with any rule's ``scores``: the available pair of the largest score or, with
    probability ``eps_explor``, a uniformly random one. Ties of the argmax go to the first pair
    in (actions, objects) order.

    ``available`` restricts both branches to pairs that can still be observed (a finite pool).
    """
    if not 0.0 <= eps_explor <= 1.0:
        raise InvalidInputError(f"eps_explor must lie in [0, 1], got {eps_explor}")
    pairs = [(a, o) for a in actions for o in objects]
    allowed = set(pairs if available is None else available)
    pairs = [p for p in pairs if p in allowed]
    if not pairs:
        raise InvalidInputError("no (action, object) pair is available")
    if rng.uniform() < eps_explor:
        # Uniform over actions, then over objects, among what is still available.
        acts = [a for a in actions if any((a, o) in allowed for o in objects)]
        a = acts[int(rng.integers(len(acts)))]
        objs = [o for o in objects if (a, o) in allowed]
        o = objs[int(rng.integers(len(objs)))]
        return Selection(a, o, True, float(scores.get((a, o), np.nan)))
    best = max(pairs, key=lambda p: (scores[p], -pairs.index(p)))
    return Selection(best[0], best[1], False, float(scores[best]))
