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

import hashlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
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


__all__ = [
    "CALIBRATION_OBJECTS",
    "CALIBRATION_TOUCHES",
    "FALSE_ALARM_RATE",
    "Recognition",
    "recognise",
    "Calibration",
    "CalibrationScores",
    "calibrate",
    "calibration_parts",
    "calibration_scores",
]

#: The share of touches of known objects that the default threshold flags as new.
FALSE_ALARM_RATE = 0.05
#: At most this many of a library's touches choose its novelty threshold (a quantile), and at
#: most this many of its objects estimate its detection rate (a mean), drawn at random: the
#: sampling error of a 95 % quantile from 4,000 touches is about ±0.35 pp of coverage.
CALIBRATION_TOUCHES = 4000
CALIBRATION_OBJECTS = 500
#: Touches are scored in blocks of about this many (touch, object) pairs.
RECOGNITION_BLOCK = 2_000_000


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
    return identity.log_likelihoods_each(X)


def _columns(identity: ObjectIdentity, objects: list[str]) -> np.ndarray:
    """Where each of ``identity``'s objects stands in the library's list ``objects``."""
    where = {o: k for k, o in enumerate(objects)}
    return np.array([where[o] for o in identity.objects_], dtype=np.int64)


def _sample(n: int, most: int, seed: int) -> np.ndarray:
    """All of ``range(n)``, or ``most`` of them drawn at random (sorted)."""
    if n <= most:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size=most, replace=False))


@dataclass(frozen=True)
class CalibrationScores:
    """What a library's calibration is chosen from, for any false-alarm rate: the novelty of
    its touches, each scored by the library without it (``held_in``: every touch, or
    :data:`CALIBRATION_TOUCHES` drawn at random), and of its objects' touches, each object
    scored by the library without it (``held_out``: every object's, or
    :data:`CALIBRATION_OBJECTS` objects'); ``touches``: how many touches the library holds.
    Computed once per library (saved with it) and reused by every recognition."""

    held_in: np.ndarray
    held_out: np.ndarray
    touches: int

    def calibration(self, false_alarm_rate: float = FALSE_ALARM_RATE) -> Calibration:
        if not 0.0 < false_alarm_rate < 1.0:
            raise InvalidInputError(f"false_alarm_rate must lie in (0, 1), got {false_alarm_rate}")
        threshold = float(np.quantile(self.held_in, 1.0 - false_alarm_rate))
        out = self.held_out
        return Calibration(
            threshold=threshold,
            false_alarm_rate=false_alarm_rate,
            detection_rate=float(np.mean(out > threshold)) if out.size else 0.0,
            touches=self.touches,
        )


def require_identities(prior: Library, actions: Iterable[str]) -> dict[str, ObjectIdentity]:
    """Each action's identity model, or the error that the library cannot recognise with it
    (no object observed twice: no noise to judge by, and nothing to calibrate on), before
    anything is computed."""
    identities = {}
    for action in actions:
        identity = prior[action].identity
        if identity is None:
            raise InvalidInputError(
                f"action {action!r}: no object of the library was observed twice"
            )
        identities[action] = identity
    return identities


def calibrate(
    prior: Library,
    false_alarm_rate: float = FALSE_ALARM_RATE,
    scores: CalibrationScores | None = None,
) -> Calibration:
    """The library's novelty threshold for ``false_alarm_rate`` (see :class:`Calibration`),
    from its :class:`CalibrationScores` (computed here unless given)."""
    if not 0.0 < false_alarm_rate < 1.0:
        raise InvalidInputError(f"false_alarm_rate must lie in (0, 1), got {false_alarm_rate}")
    return (scores or calibration_scores(prior)).calibration(false_alarm_rate)


#: Each process's part of a calibration: at least this many parts, each of whole touches or
#: objects.
CALIBRATION_PARTS = 16


def _part_counts(touches: int, objects: int) -> tuple[int, int]:
    """How many parts the sampled touches and left-out objects are scored in:
    :data:`CALIBRATION_PARTS` each (fewer only if there are fewer). Each part scores its
    touches in blocks whose (touches × objects) matrices stay within :data:`RECOGNITION_BLOCK`
    entries."""
    t, o = min(touches, CALIBRATION_TOUCHES), min(objects, CALIBRATION_OBJECTS)
    return max(min(CALIBRATION_PARTS, t), 1), max(min(CALIBRATION_PARTS, o), 1)


def calibration_parts(prior: Library) -> int:
    """How many parts :func:`calibration_scores` computes the library's scores in."""
    keys, _ = _touches({a: ap.observations for a, ap in prior.actions.items()})
    return sum(_part_counts(len(keys), len(prior.objects)))


def calibration_scores(
    prior: Library, parallel_map: Any = None, progress: Any = None
) -> CalibrationScores:
    """The library's :class:`CalibrationScores`. Each touch is scored by the library without it,
    and each object's touches by the library without that object: exact leave-one-out models,
    computed from the identity model's sums (:mod:`aptkt.learning.identity`). A library of more
    than :data:`CALIBRATION_TOUCHES` touches is judged on that many of them drawn at random,
    and the detection rate on :data:`CALIBRATION_OBJECTS` of its objects: a quantile and a
    rate, estimated from a sample (their sampling error is about ±0.5 pp at the default rate),
    at a cost that grows with the library only as the scoring of one touch does.

    ``parallel_map``: an executor's ``imap_unordered`` (``(fn, items)`` → ``(index, result)``
    pairs) to score the parts elsewhere — processes or a cluster, each sent the library's
    observations in its feature space, not the library; ``progress.update(1)`` after each
    part (:func:`calibration_parts`)."""
    data = _LibraryData.of(prior)
    chosen = _sample(len(data.keys), CALIBRATION_TOUCHES, seed=0)
    left_out = _sample(len(data.objects), CALIBRATION_OBJECTS, seed=1)
    n_touch_parts, n_object_parts = _part_counts(len(data.keys), len(data.objects))
    touch_parts = np.array_split(chosen, n_touch_parts)
    object_parts = np.array_split(left_out, n_object_parts)
    tasks = [("in", data, part) for part in touch_parts] + [
        ("out", data, part) for part in object_parts
    ]
    results: list[np.ndarray] = [np.zeros(0)] * len(tasks)
    if parallel_map is None:
        identities = {a: ap.identity for a, ap in prior.actions.items()}
        done: Any = ((i, _score_part(task, identities)) for i, task in enumerate(tasks))
    else:
        done = parallel_map(_score_part, tasks)
    for i, result in done:
        results[i] = result
        if progress is not None:
            progress.update(1)
    held_in = [r for t, r in zip(tasks, results) if t[0] == "in"]
    held_out = [r for t, r in zip(tasks, results) if t[0] == "out"]
    return CalibrationScores(
        held_in=np.concatenate(held_in), held_out=np.concatenate(held_out), touches=len(data.keys)
    )


@dataclass(frozen=True)
class _LibraryData:
    """What a part of a calibration needs of a library, as plain arrays: its objects, its
    touches, and per action the observations in its feature space, their objects and touches."""

    objects: list[str]
    keys: list[tuple[str, int]]
    actions: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]

    @classmethod
    def of(cls, prior: Library) -> _LibraryData:
        table = {a: ap.observations for a, ap in prior.actions.items()}
        keys, index = _touches(table)
        actions = {
            a: (
                ap.training_features(),
                np.asarray(ap.observations.objects).astype(str),
                index[a],
            )
            for a, ap in prior.actions.items()
        }
        return cls(list(prior.objects), keys, actions)

    @cached_property
    def token(self) -> str:
        """What identifies these observations (a process that scores several parts of one
        library fits its identity models once)."""
        digest = hashlib.sha256()
        for a, (X, labels, _) in self.actions.items():
            digest.update(a.encode())
            digest.update(np.ascontiguousarray(X).tobytes())
            digest.update("\0".join(labels.tolist()).encode())
        return digest.hexdigest()

    def identities(self) -> dict[str, ObjectIdentity | None]:
        """The identity model of each action (None without a repeated observation), fitted
        once per process and library."""
        cached = _IDENTITIES.get(self.token)
        if cached is not None:
            return cached
        out: dict[str, ObjectIdentity | None] = {}
        for a, (X, labels, _) in self.actions.items():
            names = set(labels.tolist())
            repeated = len(names) >= 2 and labels.size > len(names)
            out[a] = ObjectIdentity(X, labels) if repeated else None
        _IDENTITIES.clear()  # one library at a time: the last one
        _IDENTITIES[self.token] = out
        return out


#: The identity models of the library whose calibration parts this process scores.
_IDENTITIES: dict[str, dict[str, ObjectIdentity | None]] = {}


def _held_in(
    data: _LibraryData,
    identities: Mapping[str, ObjectIdentity | None],
    touches: np.ndarray,
) -> np.ndarray:
    """The novelty of each of ``touches`` (indices into the library's touches) scored by the
    library without it."""
    objects = data.objects
    position = np.full(len(data.keys), -1, dtype=np.int64)
    position[touches] = np.arange(touches.size)
    per_action: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    local: dict[str, np.ndarray] = {}
    for action, (_, _, touch) in data.actions.items():
        rows = np.flatnonzero(position[touch] >= 0)
        identity = identities[action]
        lo = np.full((rows.size, len(objects)), -np.inf)
        ln = np.zeros(rows.size)
        if identity is not None:
            o, n = identity.held_in_log_likelihoods(rows)
            lo[:, _columns(identity, objects)] = o
            ln = n
        per_action[action] = (lo, ln)
        local[action] = position[touch[rows]]
    old, new, _ = _fused(per_action, local, touches.size, len(objects))
    return _posterior(old, new)[1]


def _score_part(
    task: tuple[str, _LibraryData, np.ndarray],
    identities: Mapping[str, ObjectIdentity | None] | None = None,
) -> np.ndarray:
    """The novelty of one part of a calibration: the touches ``part`` (indices into the
    library's touches), each scored without it ("in"), or the touches of the objects ``part``
    (indices into its objects), each object left out ("out")."""
    kind, data, part = task
    if part.size == 0:
        return np.zeros(0)
    if identities is None:  # in another process: rebuilt from the observations
        identities = data.identities()
    objects = data.objects
    if kind == "in":
        step = max(1, RECOGNITION_BLOCK // max(len(objects), 1))
        return np.concatenate(
            [_held_in(data, identities, part[k : k + step]) for k in range(0, part.size, step)]
        )
    scores = []
    for k in part:
        name = objects[int(k)]
        per_action, touch_of = {}, {}
        for action, (_, labels, touch) in data.actions.items():
            mine = np.flatnonzero(labels == name)
            if mine.size == 0:
                continue
            identity = identities[action]
            lo = np.full((mine.size, len(objects)), -np.inf)
            ln = np.zeros(mine.size)
            if identity is not None:
                scored = identity.held_out_log_likelihoods(identity.objects_.index(name))
                if scored is not None:
                    # The identity model's rows of an object are in the observations' order.
                    lo[:, _columns(identity, objects)] = scored[0]
                    ln = scored[1]
            per_action[action] = (lo, ln)
            touch_of[action] = touch[mine]
        touches = np.unique(np.concatenate(list(touch_of.values())))
        local = {a: np.searchsorted(touches, t) for a, t in touch_of.items()}
        old, new, _ = _fused(per_action, local, touches.size, len(objects))
        scores.append(_posterior(old, new)[1])
    return np.concatenate(scores) if scores else np.zeros(0)


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

    def __repr__(self) -> str:
        acc = self.accuracy()
        parts = [
            f"{len(self)} touches of {len(set(self.object))} objects",
            f"library of {len(self.library)} objects",
            f"{int(np.sum(~np.asarray(self.known, dtype=bool)))} flagged new",
        ]
        if acc is not None:
            parts.append(f"accuracy {acc:.3f} on the library's objects")
        parts.append(f"false-alarm rate {self.calibration.false_alarm_rate:g}")
        return f"Recognition({'; '.join(parts)})"

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
    identities = require_identities(prior, table)
    cal = calibration or calibrate(prior, false_alarm_rate)
    objects = prior.objects
    keys, index = _touches(table)
    features = {}
    for action, obs in table.items():
        identity = identities[action]
        features[action] = (
            identity,
            _columns(identity, objects),
            prior[action].pipeline.transform(obs)[0],
        )
    n = len(keys)
    best = np.zeros(n, dtype=np.int64)
    second = np.zeros(n, dtype=np.int64)
    probability = np.zeros(n)
    novelty = np.zeros(n)
    # Touches in blocks: a block's (touches × objects) matrices stay small whatever the size of
    # the library.
    block = max(1, RECOGNITION_BLOCK // max(len(objects), 1))
    for first in range(0, n, block):
        stop = min(first + block, n)
        per_action, local = {}, {}
        for action, (identity, columns, X) in features.items():
            rows = np.flatnonzero((index[action] >= first) & (index[action] < stop))
            lo, ln = _likelihoods(identity, X[rows])
            full = np.full((rows.size, len(objects)), -np.inf)
            full[:, columns] = lo
            per_action[action] = (full, ln)
            local[action] = index[action][rows] - first
        old, new, _ = _fused(per_action, local, stop - first, len(objects))
        log_post, nov = _posterior(old, new)
        top = np.argmax(log_post, axis=1)
        at = np.arange(stop - first)
        known_mass = logsumexp(log_post, axis=1)
        probability[first:stop] = np.exp(log_post[at, top] - known_mass)
        log_post[at, top] = -np.inf
        best[first:stop] = top
        second[first:stop] = np.argmax(log_post, axis=1)
        novelty[first:stop] = nov
    acts: dict[int, list[str]] = {}
    for action, rows in index.items():
        for r in rows:
            if action not in acts.setdefault(int(r), []):
                acts[int(r)].append(action)
    return Recognition(
        library=list(objects),
        calibration=cal,
        object=[k[0] for k in keys],
        trial=[k[1] for k in keys],
        actions=["+".join(acts[k]) for k in range(n)],
        predicted=[objects[int(best[k])] for k in range(n)],
        probability=probability,
        runner_up=[objects[int(second[k])] if len(objects) > 1 else "" for k in range(n)],
        novelty=novelty,
        known=novelty <= cal.threshold,
    )
