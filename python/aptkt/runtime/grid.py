"""What the simulated generator and the robot's collection share: a grid of trials."""

from __future__ import annotations

from collections.abc import Iterator

from aptkt.actions import ExploratoryAction

__all__ = ["TrialGrid"]


class TrialGrid:
    """Every action ``repetitions`` times on every object, trial numbers from ``first_trial``.
    Mixed into the (frozen dataclass) plans that declare those four fields."""

    objects: tuple[str, ...]
    actions: tuple[ExploratoryAction, ...]
    repetitions: int
    first_trial: int

    def trials(self) -> Iterator[tuple[str, ExploratoryAction, int]]:
        """(object, action, trial) in the order they are recorded and written: trial by trial,
        so that a partial file holds some of every object and action alike, and a robot's
        objects can be re-placed between trials (paper §5.2)."""
        for t in range(self.first_trial, self.first_trial + self.repetitions):
            for obj in self.objects:
                for act in self.actions:
                    yield obj, act, t

    def __len__(self) -> int:
        return len(self.objects) * len(self.actions) * self.repetitions
