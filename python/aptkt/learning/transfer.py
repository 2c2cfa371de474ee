"""From where and how much to transfer (paper §4.6, Eq. 3).

For a new object j and an action α, the prior observation model of α gives, for each of j's
observations, a posterior over the old objects. Their mean ``p̄_i`` measures how much j is like
old object i. The most related old object ``i* = argmax p̄_i`` is transferred with relatedness
``λ = p̄_i*`` unless ``p̄_i* < ε_neg``, in which case nothing is transferred.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["TransferDecision", "mean_posteriors", "decide_transfer", "TRANSFER_MODES"]

#: "paper": the single most related prior per new object (Eq. 3); "none": the baseline.
TRANSFER_MODES = ("paper", "none")


@dataclass(frozen=True)
class TransferDecision:
    """What one new object's classifier of one action receives from the prior knowledge."""

    new_object: str
    old_objects: tuple[str, ...]
    mean_posterior: tuple[float, ...]
    source: str | None
    transfer_lambda: float

    @property
    def transfers(self) -> bool:
        return self.source is not None

    def as_dict(self) -> dict:
        return {
            "new_object": self.new_object,
            "source": self.source,
            "lambda": self.transfer_lambda,
            "mean_posterior": dict(zip(self.old_objects, self.mean_posterior)),
        }


def mean_posteriors(old_posteriors: np.ndarray) -> np.ndarray:
    """``p̄_i``: the mean over a new object's observations (rows) of the old posteriors."""
    p = np.asarray(old_posteriors, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] == 0:
        raise ValueError(
            f"expected a (n_observations >= 1, n_old_objects) array, got shape {p.shape}"
        )
    return p.mean(axis=0)


def decide_transfer(
    new_object: str,
    old_objects: Sequence[str],
    old_posteriors: np.ndarray,
    eps_neg: float,
    mode: str = "paper",
) -> TransferDecision:
    """Eq. 3: transfer the most related old object if its mean posterior reaches ``eps_neg``."""
    if mode not in TRANSFER_MODES:
        raise ValueError(f"transfer mode must be one of {TRANSFER_MODES}, got {mode!r}")
    if not 0.0 <= eps_neg <= 1.0:
        raise ValueError(f"eps_neg must lie in [0, 1], got {eps_neg}")
    p_bar = mean_posteriors(old_posteriors)
    if p_bar.shape[0] != len(old_objects):
        raise ValueError(f"{len(old_objects)} old objects but posteriors over {p_bar.shape[0]}")
    best = int(np.argmax(p_bar))
    related = mode == "paper" and p_bar[best] >= eps_neg
    return TransferDecision(
        new_object=str(new_object),
        old_objects=tuple(str(o) for o in old_objects),
        mean_posterior=tuple(float(v) for v in p_bar),
        source=str(old_objects[best]) if related else None,
        transfer_lambda=float(p_bar[best]) if related else 0.0,
    )
