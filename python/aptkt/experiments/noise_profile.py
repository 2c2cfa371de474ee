"""How a data set's noise looks, per action and modality: how far apart the objects lie in
units of the noise, how much repeated observations of one object drift from the first half of
its trials to the second, and how much the noise differs from object to object. Each is given
with what it would be for stationary noise that is the same for every object (the simulated
world's old assumption), so that a real sensor and the simulated one can be compared."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aptkt.learning.observations import ObservationTable
from aptkt.learning.pipeline import within_object_residuals

__all__ = ["NoiseProfile", "noise_profile"]


@dataclass(frozen=True)
class NoiseProfile:
    """One modality of one action, averaged over its columns."""

    action: str
    modality: str
    columns: int
    #: Standard deviation of the object means over the pooled within-object standard deviation.
    separation: float
    #: Mean |second-half mean − first-half mean| of each object (trials in their order), in
    #: within-object SDs, over what stationary noise gives (√(2/π)·√(1/n₁ + 1/n₂)): 1 is no drift.
    drift: float
    #: Standard deviation over objects of log10(object SD / pooled SD), over what estimation
    #: alone gives with equal noise (≈ 0.434 / √(2(n − 1))): 1 is the same noise for every object.
    heterogeneity: float

    def as_dict(self) -> dict[str, float | str | int]:
        return dict(self.__dict__)


def noise_profile(table: ObservationTable) -> list[NoiseProfile]:
    out = []
    for action, obs in table.items():
        objects = np.asarray(obs.objects)
        names = list(dict.fromkeys(objects.tolist()))
        order = np.lexsort((np.asarray(obs.trials), objects))
        for modality, X in obs.modalities.items():
            X = np.asarray(X, dtype=np.float64)
            R, dof = within_object_residuals(X, objects)
            if dof < len(names) or len(names) < 2:
                continue
            pooled = np.sqrt((R**2).sum(axis=0) / dof)
            keep = pooled > 0
            if not keep.any():
                continue
            means = np.array([X[objects == o].mean(axis=0) for o in names])
            separation = float(np.mean(means.std(axis=0, ddof=1)[keep] / pooled[keep]))
            drifts, expected, spreads, n_per = [], [], [], []
            for o in names:
                rows = order[objects[order] == o]
                n = rows.size
                if n < 4:
                    continue
                first, second = X[rows[: n // 2]], X[rows[n // 2 :]]
                shift = np.abs(second.mean(axis=0) - first.mean(axis=0))[keep] / pooled[keep]
                drifts.append(shift.mean())
                expected.append(
                    math.sqrt(2 / math.pi) * math.sqrt(1 / len(first) + 1 / len(second))
                )
                sd = X[rows].std(axis=0, ddof=1)[keep] / pooled[keep]
                spreads.append(np.log10(np.maximum(sd, 1e-12)))
                n_per.append(n)
            if len(drifts) < 2:
                continue
            logs = np.array(spreads)  # objects × columns
            chance = 0.4343 / math.sqrt(2 * (np.mean(n_per) - 1))
            out.append(
                NoiseProfile(
                    action=action,
                    modality=modality,
                    columns=int(keep.sum()),
                    separation=separation,
                    drift=float(np.mean(drifts) / np.mean(expected)),
                    heterogeneity=float(np.mean(logs.std(axis=0, ddof=1)) / chance),
                )
            )
    return out
