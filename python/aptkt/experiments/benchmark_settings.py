"""What a benchmark is asked to do (:class:`BenchmarkSettings`), apart from the benchmark itself:
the command line checks its arguments and the table against them before the learner and its
numerical libraries are loaded, so a mistake is refused in a fraction of a second."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from aptkt.errors import FeatureTableError, InvalidInputError
from aptkt.learning.config import LearnerConfig

__all__ = [
    "PRIOR_CHOICES",
    "BenchmarkSettings",
    "check_enough_objects",
    "check_lifelong_objects",
    "check_recognition_objects",
]

#: How the prior objects of a group are chosen.
PRIOR_CHOICES = ("random", "nearest", "farthest")


@dataclass(frozen=True)
class BenchmarkSettings:
    """``libraries``: the library sizes (prior objects per group) to compare, in increasing
    order; one size is the paper's Fig. 7, several are its Fig. 9 question."""

    groups: int = 60
    new_objects: int = 5
    libraries: tuple[int, ...] = (3,)
    budget: int = 20
    seed: int = 0
    choices: tuple[str, ...] = PRIOR_CHOICES
    actions: tuple[str, ...] | None = None
    config: LearnerConfig = LearnerConfig()

    def __post_init__(self) -> None:
        for name in ("groups", "new_objects"):
            if getattr(self, name) < (2 if name != "groups" else 1):
                raise InvalidInputError(f"{name} must be >= {2 if name != 'groups' else 1}")
        sizes = tuple(int(k) for k in self.libraries)
        object.__setattr__(self, "libraries", sizes)
        if not sizes or min(sizes) < 2 or list(sizes) != sorted(set(sizes)):
            raise InvalidInputError(
                f"library sizes must be distinct, increasing and >= 2, got {list(sizes)}"
            )
        if self.budget < 0:
            raise InvalidInputError(f"budget must be >= 0, got {self.budget}")
        unknown = [c for c in self.choices if c not in PRIOR_CHOICES]
        if unknown or not self.choices:
            raise InvalidInputError(f"choices must be among {PRIOR_CHOICES}, got {self.choices}")

    @property
    def prior_objects(self) -> int:
        """The largest library's size."""
        return self.libraries[-1]


def check_enough_objects(objects: Sequence[str], s: BenchmarkSettings) -> None:
    """A group needs its new objects and its largest library, all distinct."""
    if len(objects) < s.new_objects + s.prior_objects:
        raise FeatureTableError(
            f"{s.new_objects} new and {s.prior_objects} prior objects need at least "
            f"{s.new_objects + s.prior_objects} objects; the table has {len(objects)}"
        )


def check_recognition_objects(objects: Sequence[str], library: int, unseen: int) -> None:
    """A recognition draw needs its library and its unseen objects, all distinct."""
    if len(objects) < library + unseen:
        raise FeatureTableError(
            f"a library of {library} and {unseen} unseen objects need {library + unseen} objects; "
            f"the table has {len(objects)}"
        )


def check_lifelong_objects(objects: Sequence[str], batch: int) -> None:
    """A lifelong order needs a starting library and one batch."""
    if len(objects) < 2 * batch:
        raise FeatureTableError(
            f"a lifelong benchmark in batches of {batch} needs at least {2 * batch} objects "
            f"(a starting library and one batch); the table has {len(objects)}"
        )
