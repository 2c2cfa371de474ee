"""Active selection of the next (action, object) pair (AT-LPP, paper §4.7, Eq. 4).

``UNC(α, c_j)`` is the mean Shannon entropy of the new-object posterior over the observations
collected so far for action α on object c_j. With probability ``1 - ε_explor`` the pair with the
largest uncertainty is explored next; otherwise action and object are drawn uniformly.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = ["entropy", "uncertainty", "Selection", "select_next"]

Pair = tuple[str, str]


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


@dataclass(frozen=True)
class Selection:
    action: str
    object: str
    explored: bool
    uncertainty: float


def select_next(
    unc: Mapping[Pair, float],
    actions: Sequence[str],
    objects: Sequence[str],
    eps_explor: float,
    rng: np.random.Generator,
    available: Sequence[Pair] | None = None,
) -> Selection:
    """Eq. 4. Ties of the argmax go to the first pair in (actions, objects) order.

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
        return Selection(a, o, True, float(unc.get((a, o), np.nan)))
    best = max(pairs, key=lambda p: (unc[p], -pairs.index(p)))
    return Selection(best[0], best[1], False, float(unc[best]))
