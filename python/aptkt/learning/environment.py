"""Where observations come from: the learner asks an environment for one observation of
(action, object). A live robot (the simulated world, or the UR10) explores the object; a pool
replays pre-recorded observations (the paper's offline protocol).

An environment may say what computes its observations (an ``extraction`` attribute, see
:attr:`~aptkt.learning.observations.Observations.extraction`): a robot's are this package's
extraction of this skin, a pool's are its observations'. One that does not say is any sensor's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np

from aptkt.errors import AptktError, UnknownNameError
from aptkt.learning.extract import observe_recording
from aptkt.learning.observations import Observations, ObservationTable, common_extraction
from aptkt.learning.pipeline import SKIN_EXTRACTION

__all__ = [
    "Environment",
    "PoolEnvironment",
    "PoolExhaustedError",
    "PrefetchedEnvironment",
    "RecordingEnvironment",
]


class PoolExhaustedError(AptktError):
    """A pool has no unused observation left for an (action, object) pair."""


@runtime_checkable
class Environment(Protocol):
    def observe(self, action: str, obj: str) -> Mapping[str, np.ndarray]:
        """One new feature observation (modality name -> raw vector)."""
        ...

    def available(self, action: str, obj: str) -> bool:
        """Whether another observation of the pair can be had."""
        ...


class PoolEnvironment:
    """Pre-recorded observations, drawn without replacement in a seeded random order."""

    def __init__(self, table: ObservationTable, seed: int = 0) -> None:
        self.table = dict(table)
        #: What computed the pool's observations (None if they do not say).
        self.extraction = common_extraction(self.table.values())
        rng = np.random.default_rng(seed)
        self._queues: dict[tuple[str, str], list[int]] = {}
        for action, obs in self.table.items():
            for obj in obs.object_names:
                idx = np.flatnonzero(obs.objects == obj)
                self._queues[(action, obj)] = list(rng.permutation(idx))

    def available(self, action: str, obj: str) -> bool:
        return bool(self._queues.get((action, obj)))

    def remaining(self, action: str, obj: str) -> int:
        return len(self._queues.get((action, obj), []))

    def unused(self, action: str) -> Observations:
        """The pool's observations of ``action`` not drawn yet: touches of the new objects
        from the same recordings as those learned, that no learner has seen."""
        if action not in self.table:
            raise UnknownNameError(f"the pool has no observations of action {action!r}")
        rows = [i for (a, _), queue in self._queues.items() if a == action for i in queue]
        return self.table[action].take(np.array(sorted(rows), dtype=np.int64))

    def observe(self, action: str, obj: str) -> Mapping[str, np.ndarray]:
        if (action, obj) not in self._queues:
            raise UnknownNameError(
                f"the pool has no observations of action {action!r} on object {obj!r}"
            )
        queue = self._queues[(action, obj)]
        if not queue:
            raise PoolExhaustedError(
                f"every pooled observation of {action!r} on {obj!r} has been used"
            )
        return self.table[action].row(int(queue.pop(0)))


class RecordingEnvironment:
    """Observations made live: every request runs the exploratory action on a robot — the
    simulated world (``SimWorld(...).explore``) or a hardware session — and extracts its
    features. Trial numbers count up per (action, object) from ``first_trial``; every recording
    is handed to ``on_recording`` (e.g. a :class:`~aptkt.data.DatasetWriter`'s ``append``) so
    nothing observed is lost.
    """

    #: Its observations are this package's extraction of this skin's recordings.
    extraction = SKIN_EXTRACTION

    def __init__(
        self,
        explore: Callable[[str, Any, int], Any],
        actions: Mapping[str, Any],
        *,
        first_trial: int = 0,
        settings: Any = None,
        on_recording: Callable[[Any], Any] | None = None,
    ) -> None:
        self._explore = explore
        self.actions = dict(actions)
        self._next: dict[tuple[str, str], int] = {}
        self._first = int(first_trial)
        self._settings = settings
        self._on_recording = on_recording

    def available(self, action: str, obj: str) -> bool:
        return action in self.actions

    def observe(self, action: str, obj: str) -> Mapping[str, np.ndarray]:
        if action not in self.actions:
            raise UnknownNameError(f"unknown action {action!r}; known: {sorted(self.actions)}")
        trial = self._next.get((action, obj), self._first)
        self._next[(action, obj)] = trial + 1
        recording = self._explore(obj, self.actions[action], trial)
        if self._on_recording is not None:
            self._on_recording(recording)
        return observe_recording(recording, self.actions[action], self._settings)


class PrefetchedEnvironment:
    """Another environment whose first observation of some (action, object) pairs was made
    already — e.g. the touches that recognised which objects are new — and is handed out
    before the robot is asked again."""

    def __init__(
        self, env: Environment, prefetched: Mapping[tuple[str, str], Mapping[str, np.ndarray]]
    ) -> None:
        self._env = env
        self._ready = dict(prefetched)
        self.extraction = getattr(env, "extraction", None)

    def available(self, action: str, obj: str) -> bool:
        return (action, obj) in self._ready or self._env.available(action, obj)

    def observe(self, action: str, obj: str) -> Mapping[str, np.ndarray]:
        if (action, obj) in self._ready:
            return self._ready.pop((action, obj))
        return self._env.observe(action, obj)
