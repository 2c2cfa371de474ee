"""Objects beyond any real data set: a population fitted on a real feature table, and as many
synthetic objects drawn from it as a benchmark of a growing library needs.

The generative model is the library's own model of its objects (the two-covariance model of
:mod:`aptkt.learning.identity`), fitted per action on the table's observations, each column
first divided by its pooled within-object standard deviation:

* an object's mean is drawn from N(centre, s² B): B the covariance of the table's object means
  less the noise they still carry (without the identity model's isotropic prior, which would
  let new objects differ where the table's never do);
* its noise level from the log-normal distribution of the table's objects' levels (each
  object's residual variance over the pooled one);
* each of its observations from N(mean, level · W), W the pooled within-object covariance.

The observations are then put back into the table's units. The spread's factor s is fitted so
that one observation of each of as many synthetic objects as the table holds tells them apart
as often as one of each of the table's objects does (nearest single observation, in the noise's
metric; :func:`one_shot_accuracy`): real objects crowd where a Gaussian of their covariance
would spread them (measured on the BioTac set's 20 materials: 0.85 for the materials, 0.93–0.97
for a Gaussian of their covariance, s ≈ 0.7). So the synthetic objects are as hard to tell
apart as the real ones, and each is as noisy as a real one could be. What the model does not
keep is stated, not hidden: the features' non-Gaussian shapes, correlations between the
actions of one object (each action's mean is drawn on its own), drift between sessions, and
look-alike pairs beyond the ones a Gaussian population produces. Features that
this skin's extraction takes the logarithm of are generated as their logarithms, and the
synthetic observations say nothing of their extraction: they are z-scored as another sensor's.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.learning.identity import ObjectIdentity
from aptkt.learning.observations import Observations, ObservationTable
from aptkt.learning.pipeline import transforms_of

__all__ = ["ActionPopulation", "ObjectPopulation"]


@dataclass(frozen=True)
class ActionPopulation:
    """One action's population: ``modalities`` (name -> number of columns, in order); the
    columns' offset and unit (each column's mean and pooled within-object standard deviation);
    in those units the centre and the Cholesky factors of B and W; and the mean and standard
    deviation of the objects' log noise levels."""

    modalities: dict[str, int]
    offset: np.ndarray
    unit: np.ndarray
    centre: np.ndarray
    between: np.ndarray
    within: np.ndarray
    log_level_mean: float
    log_level_sd: float
    #: The factor the between-object covariance's factor was scaled by to match the table's
    #: one-shot accuracy (1: not scaled).
    spread_scale: float = 1.0

    def draw(self, n_objects: int, trials: int, rng: np.random.Generator) -> np.ndarray:
        """(n_objects * trials, columns): each object's ``trials`` observations in turn."""
        d = self.centre.size
        means = self.centre + rng.standard_normal((n_objects, d)) @ self.between.T
        levels = np.exp(self.log_level_mean + self.log_level_sd * rng.standard_normal(n_objects))
        noise = rng.standard_normal((n_objects, trials, d)) @ self.within.T
        Z = means[:, None, :] + np.sqrt(levels)[:, None, None] * noise
        return self.offset + self.unit * Z.reshape(n_objects * trials, d)


class ObjectPopulation:
    """Per action, the population a table's objects look drawn from (see the module
    docstring). :meth:`fit` on a table; :meth:`draw` new objects."""

    def __init__(
        self,
        actions: Mapping[str, ActionPopulation],
        accuracies: Mapping[str, float] | None = None,
    ) -> None:
        if not actions:
            raise InvalidInputError("a population needs at least one action")
        self.actions = dict(actions)
        #: Per action, the table's one-shot nearest-neighbour accuracy the population matches.
        self.accuracies = dict(accuracies or {})

    def __repr__(self) -> str:
        parts = ", ".join(
            f"{a} ({sum(p.modalities.values())} columns)" for a, p in self.actions.items()
        )
        return f"ObjectPopulation({parts})"

    @classmethod
    def fit(cls, table: ObservationTable) -> ObjectPopulation:
        """The population of ``table``'s objects, per action (each needs at least two objects
        and a repeated observation)."""
        actions, accuracies = {}, {}
        for name, obs in table.items():
            X = _generated_space(obs)
            objects = np.asarray(obs.objects)
            names = np.unique(objects)
            if names.size < 2 or objects.size - names.size < 2:
                raise InvalidInputError(
                    f"action {name!r}: a population needs at least two objects and repeated "
                    "observations of them"
                )
            offset = X.mean(axis=0)
            means = np.array([X[objects == o].mean(axis=0) for o in names])
            residuals = X - means[np.searchsorted(names, objects)]
            unit = np.sqrt((residuals**2).sum(axis=0) / (objects.size - names.size))
            # A column without noise (constant within every object) keeps its spread as unit.
            spread = X.std(axis=0)
            unit = np.where(unit > 1e-12 * np.maximum(1.0, np.abs(offset)), unit, spread)
            unit = np.where(unit > 0, unit, 1.0)
            Z = (X - offset) / unit
            identity = ObjectIdentity(Z, objects)
            logs = np.log(identity.noise_levels_)
            shape = ActionPopulation(
                modalities={m: v.shape[1] for m, v in obs.modalities.items()},
                offset=offset,
                unit=unit,
                centre=identity.centre_,
                between=np.linalg.cholesky(_between(identity)),
                within=np.linalg.cholesky(identity.within_),
                log_level_mean=float(logs.mean()),
                log_level_sd=float(logs.std(ddof=1)) if logs.size > 1 else 0.0,
            )
            target = one_shot_accuracy(Z, objects, shape.within)
            scale = _matching_spread(shape, target, names.size, int(np.median(identity.counts_)))
            actions[name] = replace(shape, between=scale * shape.between, spread_scale=scale)
            accuracies[name] = target
        return cls(actions, accuracies)

    def draw(
        self, n_objects: int, trials: int, seed: int, *, prefix: str = "synthetic"
    ) -> ObservationTable:
        """``n_objects`` new objects named ``prefix00000``, ``prefix00001``, ..., each observed
        ``trials`` times by every action (trials 0 .. trials − 1); ``seed`` decides everything,
        and objects drawn with the same seed and prefix are the same objects whatever
        ``n_objects`` is (each is drawn from its own stream)."""
        if n_objects < 1 or trials < 1:
            raise InvalidInputError(
                f"need n_objects >= 1 and trials >= 1, got {n_objects}, {trials}"
            )
        width = len(str(max(n_objects - 1, 99999)))
        names = np.array([f"{prefix}{k:0{width}d}" for k in range(n_objects)])
        out: dict[str, Observations] = {}
        for a, (action, pop) in enumerate(self.actions.items()):
            blocks = [
                pop.draw(1, trials, np.random.default_rng([seed, a, k])) for k in range(n_objects)
            ]
            X = np.concatenate(blocks)
            mods, start = {}, 0
            for m, width_m in pop.modalities.items():
                mods[m] = X[:, start : start + width_m]
                start += width_m
            out[action] = Observations(
                action, mods, np.repeat(names, trials), np.tile(np.arange(trials), n_objects)
            )
        return out


def _between(identity: ObjectIdentity) -> np.ndarray:
    """The covariance of the objects' means less the noise each mean still carries — without
    the identity model's isotropic prior, which spreads it over every column so that a new
    object may differ where the known ones never do: a population drawn from that would be
    easier to tell apart than the real one. Directions the means do not vary in get a sliver
    (a thousandth of the largest variance) so that the factor exists."""
    means = identity.means_
    centred = means - means.mean(axis=0)
    B = centred.T @ centred / max(means.shape[0] - 1, 1)
    B = B - identity.within_ * float(np.mean(1.0 / identity.counts_))
    vals, vecs = np.linalg.eigh((B + B.T) / 2)
    floor = 1e-3 * max(float(vals.max()), 1e-12)
    return vecs @ np.diag(np.maximum(vals, floor)) @ vecs.T


#: Draws of the single observations behind a one-shot accuracy, and of a population's objects
#: behind its expected one-shot accuracy.
ACCURACY_DRAWS = 20
POPULATION_DRAWS = 10
#: Halvings of the interval the spread's factor is searched in (a precision of 2⁻¹⁶ of it).
BISECTION_STEPS = 16


def one_shot_accuracy(
    Z: np.ndarray, objects: np.ndarray, within: np.ndarray, seed: int = 0
) -> float:
    """How often one observation of each object tells the objects apart: each object's other
    observations assigned to the object of the nearest single observation, in the noise's
    whitened metric (``within``: the Cholesky factor of the within-object covariance), averaged
    over :data:`ACCURACY_DRAWS` draws of the single observations."""
    W = np.linalg.solve(within, np.asarray(Z, dtype=np.float64).T).T
    labels = np.asarray(objects).astype(str)
    names, index = np.unique(labels, return_inverse=True)
    rows = [np.flatnonzero(index == k) for k in range(names.size)]
    rng = np.random.default_rng(seed)
    hits = []
    for _ in range(ACCURACY_DRAWS):
        shots = np.array([rng.choice(r) for r in rows])
        rest = np.ones(labels.size, dtype=bool)
        rest[shots] = False
        # ‖w − s‖² = ‖w‖² − 2 w·s + ‖s‖², and ‖w‖² is the same for every shot: one product.
        S = W[shots]
        d = (S**2).sum(axis=1)[None, :] - 2.0 * (W[rest] @ S.T)
        hits.append(np.mean(d.argmin(axis=1) == index[rest]))
    return float(np.mean(hits))


def _matching_spread(pop: ActionPopulation, target: float, n_objects: int, trials: int) -> float:
    """The factor of the between-object spread at which ``n_objects`` objects of the population,
    observed ``trials`` times each, are told apart by one observation each as often as the
    table's (``target``): found by bisection, each step with the same random draws, so that the
    accuracy is a smooth, increasing function of the factor."""

    objects = np.repeat(np.arange(n_objects), trials)

    def accuracy(scale: float) -> float:
        scaled = replace(pop, between=scale * pop.between)
        values = []
        for k in range(POPULATION_DRAWS):
            Z = (scaled.draw(n_objects, trials, np.random.default_rng(k)) - pop.offset) / pop.unit
            values.append(one_shot_accuracy(Z, objects, pop.within, seed=k))
        return float(np.mean(values))

    lo, hi = 0.0, 1.0
    while accuracy(hi) < target and hi < 64:
        lo, hi = hi, 2 * hi
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        if accuracy(mid) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _generated_space(obs: Observations) -> np.ndarray:
    """The observations' columns side by side, with the logarithms this skin's transforms take
    already taken (what the synthetic observations are drawn in)."""
    transforms = transforms_of(obs.extraction)
    blocks = []
    for m, values in obs.modalities.items():
        X = np.array(values, dtype=np.float64)
        logs = list(transforms[m].log_columns) if m in transforms else []
        if logs:
            X[:, logs] = np.log10(np.maximum(X[:, logs], 1e-12))
        blocks.append(X)
    return np.hstack(blocks)
