"""Recognise what the library knows, and flag what it does not: for each touch of an object
(one or several actions on the same object and trial), the most probable known object, how
sure the library is, and whether it is one of its objects at all.

The library's generative model of its objects (:class:`~aptkt.learning.identity.
ObjectIdentity`, one per action, in that action's feature space) gives each touch a posterior
over "old object i" and "an object the library does not hold". Several actions of one touch are
independent evidence: their log-likelihoods add, as the paper's fused posteriors multiply.

* ``predicted``, ``probability``, ``runner_up``: the most probable known objects and the
  first's posterior among the known ones (P(i) / (1 − P(new))).
* ``novelty``: the log odds of "not in the library" against "one of its objects": higher means
  less like any known object.
* ``known``: novelty at most a threshold chosen on the library itself — each of its touches
  scored by the library without that touch (leave one touch out) — so that a stated share of
  touches of known objects (``false_alarm_rate``) is flagged as new. Leaving each *object* out
  estimates, on the same library, how often a new object is caught (``detection_rate``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from scipy.special import logsumexp

from aptkt.errors import InvalidInputError
from aptkt.learning.identity import NEW_OBJECT_PRIOR, ObjectIdentity
from aptkt.learning.observations import Observations
from aptkt.learning.pipeline import FeaturePipeline


class ActionKnowledge(Protocol):
    """What recognition reads of a library's knowledge of one action
    (:class:`~aptkt.learning.prior.ActionPrior` is one)."""

    @property
    def observations(self) -> Observations: ...
    @property
    def pipeline(self) -> FeaturePipeline: ...
    @property
    def identity(self) -> ObjectIdentity | None: ...
    def training_features(self) -> np.ndarray: ...


class Library(Protocol):
    """What recognition reads of a library (:class:`~aptkt.learning.prior.PriorKnowledge` is
    one). A protocol rather than the class: the library calls this module."""

    @property
    def actions(self) -> Mapping[str, ActionKnowledge]: ...
    @property
    def objects(self) -> list[str]: ...
    def __contains__(self, action: object) -> bool: ...
    def __getitem__(self, action: str) -> ActionKnowledge: ...


__all__ = ["FALSE_ALARM_RATE", "Recognition", "recognise", "Calibration", "calibrate"]

#: The share of touches of known objects that the default threshold flags as new.
FALSE_ALARM_RATE = 0.05


@dataclass(frozen=True)
class Calibration:
    """The novelty threshold chosen on the library: the (1 − ``false_alarm_rate``) quantile of
    its own touches' novelty, each scored without it; and the share of its objects' touches
    flagged as new when each object is left out (``detection_rate``: how often a new object is
    caught, estimated on the library's own objects)."""

    threshold: float
    false_alarm_rate: float
    detection_rate: float
    touches: int


def _touches(
    table: Mapping[str, Observations],
) -> tuple[list[tuple[str, int]], dict[str, np.ndarray]]:
    """The touches — (object, trial) pairs over every action — in order of first appearance, and
    per action the touch index of each of its rows."""
    keys: dict[tuple[str, int], int] = {}
    index: dict[str, np.ndarray] = {}
    for action, obs in table.items():
        rows = []
        for o, t in zip(np.asarray(obs.objects).astype(str), np.asarray(obs.trials)):
            rows.append(keys.setdefault((str(o), int(t)), len(keys)))
        index[action] = np.asarray(rows, dtype=np.int64)
    return list(keys), index


def _fused(
    per_action: Mapping[str, tuple[np.ndarray, np.ndarray]],
    index: Mapping[str, np.ndarray],
    n_touches: int,
    n_objects: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Summed log-likelihoods per touch — (touches × old objects), (touches,) for "new" — and how
    many actions each touch had. Several observations of one action in one touch count as
    independent too."""
    old = np.zeros((n_touches, n_objects))
    new = np.zeros(n_touches)
    count = np.zeros(n_touches, dtype=np.int64)
    for action, (lo, ln) in per_action.items():
        np.add.at(old, index[action], lo)
        np.add.at(new, index[action], ln)
        np.add.at(count, index[action], 1)
    return old, new, count


def _posterior(old: np.ndarray, new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Log posteriors (touches × old objects) and the novelty log odds (touches,)."""
    n_old = old.shape[1]
    joint = np.column_stack(
        [np.log(NEW_OBJECT_PRIOR) + new, np.log((1 - NEW_OBJECT_PRIOR) / n_old) + old]
    )
    joint -= logsumexp(joint, axis=1, keepdims=True)
    novelty = joint[:, 0] - logsumexp(joint[:, 1:], axis=1)
    return joint[:, 1:], novelty


def _likelihoods(identity: ObjectIdentity, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rows = [identity.log_likelihoods(x[None, :]) for x in X]
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])


def calibrate(prior: Library, false_alarm_rate: float = FALSE_ALARM_RATE) -> Calibration:
    """The library's novelty threshold for ``false_alarm_rate`` (see :class:`Calibration`)."""
    if not 0.0 < false_alarm_rate < 1.0:
        raise InvalidInputError(f"false_alarm_rate must lie in (0, 1), got {false_alarm_rate}")
    table = {a: ap.observations for a, ap in prior.actions.items()}
    keys, index = _touches(table)
    objects = prior.objects
    held_in: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    held_out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for action, ap in prior.actions.items():
        X = ap.training_features()
        labels = np.asarray(ap.observations.objects).astype(str)
        n_rows = X.shape[0]
        lo = np.full((n_rows, len(objects)), -np.inf)
        ln = np.zeros(n_rows)
        # Each touch scored by the library without it.
        for r in range(n_rows):
            keep = np.arange(n_rows) != r
            model = _identity(X[keep], labels[keep])
            if model is None:
                continue
            o, n = model.log_likelihoods(X[r][None, :])
            lo[r, [objects.index(name) for name in model.objects_]] = o
            ln[r] = n
        held_in[action] = (lo, ln)
        # Each object's touches scored by the library without that object.
        lo2 = np.full((n_rows, len(objects)), -np.inf)
        ln2 = np.zeros(n_rows)
        for name in sorted(set(labels.tolist())):
            mine = labels == name
            model = _identity(X[~mine], labels[~mine])
            if model is None:
                continue
            out_old, out_new = _likelihoods(model, X[mine])
            cols = np.array([objects.index(m) for m in model.objects_], dtype=np.int64)
            lo2[np.ix_(np.flatnonzero(mine), cols)] = out_old
            ln2[mine] = out_new
        held_out[action] = (lo2, ln2)
    old, new, _ = _fused(held_in, index, len(keys), len(objects))
    _, novelty = _posterior(old, new)
    threshold = float(np.quantile(novelty, 1.0 - false_alarm_rate))
    old2, new2, _ = _fused(held_out, index, len(keys), len(objects))
    _, novelty_out = _posterior(old2, new2)
    return Calibration(
        threshold=threshold,
        false_alarm_rate=false_alarm_rate,
        detection_rate=float(np.mean(novelty_out > threshold)),
        touches=len(keys),
    )


def _identity(X: np.ndarray, labels: np.ndarray) -> ObjectIdentity | None:
    names = set(labels.tolist())
    if len(names) < 2 or labels.size == len(names):
        return None
    return ObjectIdentity(X, labels)


@dataclass
class Recognition:
    """What the library says of each touch: its object, action(s) and trial, and the fields of
    the module docstring. ``library``: the library's objects; ``calibration``: how ``known``
    was decided."""

    library: list[str]
    calibration: Calibration
    object: list[str] = field(default_factory=list)
    trial: list[int] = field(default_factory=list)
    actions: list[str] = field(default_factory=list)
    predicted: list[str] = field(default_factory=list)
    probability: np.ndarray = field(default_factory=lambda: np.zeros(0))
    runner_up: list[str] = field(default_factory=list)
    novelty: np.ndarray = field(default_factory=lambda: np.zeros(0))
    known: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __len__(self) -> int:
        return len(self.object)

    def rows(self) -> list[dict[str, Any]]:
        """One dict per touch: object, action(s) (joined by "+"), trial, predicted,
        probability, runner_up, novelty, known."""
        return [
            {
                "object": self.object[k],
                "action": self.actions[k],
                "trial": self.trial[k],
                "predicted": self.predicted[k],
                "probability": float(self.probability[k]),
                "runner_up": self.runner_up[k],
                "novelty": float(self.novelty[k]),
                "known": bool(self.known[k]),
            }
            for k in range(len(self))
        ]

    def columns(self) -> dict[str, list[Any]]:
        """Column name -> values, one per touch: ``pandas.DataFrame(result.columns())`` (or
        ``pandas.DataFrame(result.rows())``) is the table; aptkt itself never imports pandas."""
        rows = self.rows()
        names = [
            "object",
            "action",
            "trial",
            "predicted",
            "probability",
            "runner_up",
            "novelty",
            "known",
        ]
        return {n: [r[n] for r in rows] for n in names}

    def in_library(self) -> np.ndarray:
        return np.isin(np.asarray(self.object), self.library)

    def accuracy(self) -> float | None:
        """The share of touches of library objects recognised as the right one (None without
        any)."""
        mine = self.in_library()
        if not mine.any():
            return None
        return float(np.mean(np.asarray(self.predicted)[mine] == np.asarray(self.object)[mine]))

    def novelty_auroc(self) -> float | None:
        """How well novelty tells touches of objects outside the library from those inside
        (the area under the ROC curve: the probability that a new object's touch scores higher
        than a known one's; ties count half); None unless both are present."""
        mine = self.in_library()
        if mine.all() or not mine.any():
            return None
        return auroc(self.novelty[~mine], self.novelty[mine])


def auroc(positive: np.ndarray, negative: np.ndarray) -> float:
    """P(a positive's score > a negative's) + ½ P(equal): the Mann–Whitney statistic."""
    p = np.asarray(positive, dtype=np.float64)[:, None]
    n = np.asarray(negative, dtype=np.float64)[None, :]
    return float(np.mean((p > n) + 0.5 * (p == n)))


def recognise(
    prior: Library,
    table: Mapping[str, Observations],
    *,
    calibration: Calibration | None = None,
    false_alarm_rate: float = FALSE_ALARM_RATE,
) -> Recognition:
    """Recognise every touch of ``table`` (action -> observations; rows of different actions
    with the same object and trial are one touch) with the library ``prior``."""
    unknown = [a for a in table if a not in prior]
    if unknown:
        raise InvalidInputError(
            f"the library has no experience of action(s) {unknown}; it has {list(prior.actions)}"
        )
    if not table or all(len(obs) == 0 for obs in table.values()):
        raise InvalidInputError("nothing to recognise: no observations")
    for action, obs in table.items():
        if obs.modality_names != prior[action].pipeline.modality_names_:
            raise InvalidInputError(
                f"action {action!r}: observations have modalities {list(obs.modality_names)}, "
                f"the library's {list(prior[action].pipeline.modality_names_)}"
            )
    cal = calibration or calibrate(prior, false_alarm_rate)
    objects = prior.objects
    keys, index = _touches(table)
    per_action = {}
    for action, obs in table.items():
        ap = prior[action]
        identity = ap.identity
        if identity is None:
            raise InvalidInputError(
                f"action {action!r}: no object of the library was observed twice"
            )
        X = ap.pipeline.transform(obs)[0]
        lo, ln = _likelihoods(identity, X)
        full = np.full((lo.shape[0], len(objects)), -np.inf)
        full[:, [objects.index(m) for m in identity.objects_]] = lo
        per_action[action] = (full, ln)
    old, new, _ = _fused(per_action, index, len(keys), len(objects))
    log_post, novelty = _posterior(old, new)
    order = np.argsort(-log_post, axis=1)
    known_mass = logsumexp(log_post, axis=1)
    acts: dict[int, list[str]] = {}
    for action, rows in index.items():
        for r in rows:
            if action not in acts.setdefault(int(r), []):
                acts[int(r)].append(action)
    n = len(keys)
    return Recognition(
        library=list(objects),
        calibration=cal,
        object=[k[0] for k in keys],
        trial=[k[1] for k in keys],
        actions=["+".join(acts[k]) for k in range(n)],
        predicted=[objects[int(order[k, 0])] for k in range(n)],
        probability=np.exp(log_post[np.arange(n), order[:, 0]] - known_mass),
        runner_up=[objects[int(order[k, 1])] if len(objects) > 1 else "" for k in range(n)],
        novelty=novelty,
        known=novelty <= cal.threshold,
    )
